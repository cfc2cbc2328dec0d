"""The hexapod as a first-order ODE dx/dt = f(t, x), advanced step by step (the FMU's core).

State x = [pose (6), twist (6)]: the pose [x, y, z, roll, pitch, yaw] of {P} in {B} and
the twist u = (v, w) of {P} relative to {B} in {B} (the generalised speeds of Kane's
equations; RPY rates are derived, so the speeds carry no RPY singularity).

Over one step the leg forces are held (zero-order hold) and the base motion is
extrapolated from the step's start by its own rates and accelerations (second-order
Taylor), so a base turning at constant acceleration is followed exactly.

Why the fixed-step methods run in C (plant.kane.HexapodKernel.advance_fixed): the FMU's
budget per communication step is ~10x an empty FMU's doStep (~1.4 µs); RK4 in Python
around the compiled right-hand side costs ~20 µs, one C call a few µs. Inputs and
outputs live in two arrays the caller may share (the FMU maps its variables onto them);
their C pointers are taken once here, so a step copies nothing. "radau" goes through
plant.integrators with the C right-hand side.
"""
import math

import numpy as np

from . import integrators, kane
from .errors import ConvergenceError, InvalidInputError, SingularConfigurationError
from .stewart import SINGULAR_RATIO, fidelity_mode, check_stroke, inverse_kinematics, jacobian


class HexapodODE:
    """The hexapod plant between communication points: hold inputs, advance, read out.

    ``inputs`` (4, 6): leg forces, base pose, base rate, base acc (held over a step).
    ``outputs`` (3, 6): leg lengths, leg rates, pose rates after the last step."""

    def __init__(self, params, fidelity="full", moving_base=True, method="rk4", max_step=1e-3,
                 inputs=None, outputs=None):
        if method not in integrators.INTEGRATORS:
            raise InvalidInputError(f"unknown integrator {method!r}; choose one of {integrators.INTEGRATORS}")
        if not max_step > 0:
            raise InvalidInputError(f"max_step must be positive, got {max_step}")
        self.params, self.method, self.max_step = params, method, max_step
        base_mode, self.legs = fidelity_mode(fidelity)
        self.base_mode = base_mode if moving_base else kane.BASE_NONE
        self.inputs = np.zeros((4, 6)) if inputs is None else inputs
        self.outputs = np.zeros((3, 6)) if outputs is None else outputs
        self.bounds = params.home_lengths + np.array(params.stroke)[:, None]
        self.t0 = 0.0
        self._kernel = params.kernel
        # the arrays are shared with the caller and written in place: checked, never copied
        self._inputs = kane.pointer(self.inputs, (4, 6), "inputs")
        self._outputs = kane.pointer(self.outputs, (3, 6), "outputs")
        self._bounds = kane.pointer(self.bounds, (2, 6), "bounds")
        self._base0 = kane.pointer(self.inputs[1:4], (3, 6), "base inputs")

    def set_inputs(self, t0, forces, base_pose=0.0, base_rate=0.0, base_acc=0.0):
        """Hold ``forces`` and the base motion given at t0 for the coming step."""
        self.t0 = t0
        for row, values in zip(self.inputs, (forces, base_pose, base_rate, base_acc)):
            row[:] = values

    def rhs(self, t, x):
        dx = np.empty(12)   # scipy's Jacobian differencing passes strided x: the kernel copies it
        det = self._kernel.rhs(x, self._inputs, self._base0, self.t0, t, self.base_mode, self.legs, dx)
        self._check_det(det)
        return dx

    def _check_det(self, det):
        if det < SINGULAR_RATIO * self.params.home_det:
            raise SingularConfigurationError(
                f"singular pose reached: |det J| is {det / self.params.home_det:.2e} of home (< {SINGULAR_RATIO})")

    def advance(self, x, h):
        """Advance x (at t0) to t0 + h in place and fill ``outputs``. Raises a PlantError
        naming the problem: NaN/inf inputs, divergence, a singular pose, a leg past its
        stroke."""
        if self.method == "radau":
            return self._advance_radau(x, h)
        substeps = max(1, math.ceil(h / self.max_step - 1e-9))
        det, status = self._kernel.advance_fixed(self.method == "rk4", substeps, x, self._inputs, self.t0, h,
                                                 self.base_mode, self.legs, self._bounds, self._outputs)
        if status == kane.OK and det >= SINGULAR_RATIO * self.params.home_det:
            return self.outputs
        if status == kane.BAD_INPUT:
            names = ("leg forces", "base pose", "base rate", "base acc")
            bad = [n for n, row in zip(names, self.inputs) if not np.isfinite(row).all()]
            raise InvalidInputError(f"{', '.join(bad)} input contains NaN or inf")
        if status == kane.DIVERGED:
            raise ConvergenceError(f"integrator {self.method} diverged over [{self.t0:.6g}, {self.t0 + h:.6g}] s "
                                   f"(substep {h / substeps:.3g} s): the state is no longer finite or bounded")
        self._check_det(det)
        check_stroke(self.params, self.outputs[0])
        return self.outputs

    def _advance_radau(self, x, h):
        if not np.isfinite(self.inputs).all():
            raise InvalidInputError("an input (leg forces or base motion) contains NaN or inf")
        if h > 0:
            x[:] = integrators.advance("radau", self.rhs, self.t0, x, h, self.max_step)
        self.outputs[0] = inverse_kinematics(self.params, x[:6])
        self.outputs[1] = jacobian(self.params, x[:6]) @ x[6:]
        self.outputs[2] = self.rhs(self.t0 + h, x)[:6]
        check_stroke(self.params, self.outputs[0])
        return self.outputs
