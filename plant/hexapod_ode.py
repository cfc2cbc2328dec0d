"""The hexapod as a first-order ODE dx/dt = f(t, x), advanced step by step (the FMU's core).

State x = [pose (6), twist (6)]: the pose [x, y, z, roll, pitch, yaw] of {P} in {B} and
the twist u = (v, w) of {P} relative to {B} in {B} (the generalised speeds of Kane's
equations; RPY rates are derived, so the speeds carry no RPY singularity).

Over one step the leg forces are held (zero-order hold) and the base motion is
extrapolated from the step's start by its own rates and accelerations (second-order
Taylor), so a base turning at constant acceleration is followed exactly.

The right-hand side is one call into the compiled kernel (plant.kane.rhs, ~5 µs): the
validated public API would cost ~30 µs a call, and RK4 calls it four times a substep.
"""
import numpy as np

from . import integrators, kane
from .errors import ConvergenceError, InvalidInputError, SingularConfigurationError
from .stewart import _FIDELITY_MODES, SINGULAR_RATIO


class HexapodODE:
    """The hexapod plant between communication points: hold inputs, advance, read out."""

    def __init__(self, params, fidelity="full", moving_base=True, method="rk4", max_step=1e-3):
        if fidelity not in _FIDELITY_MODES:
            raise InvalidInputError(f"unknown fidelity {fidelity!r}; choose one of {tuple(_FIDELITY_MODES)}")
        if method not in integrators.INTEGRATORS:
            raise InvalidInputError(f"unknown integrator {method!r}; choose one of {integrators.INTEGRATORS}")
        if not max_step > 0:
            raise InvalidInputError(f"max_step must be positive, got {max_step}")
        self.params, self.method, self.max_step = params, method, max_step
        base_mode, self.legs = _FIDELITY_MODES[fidelity]
        self.base_mode = base_mode if moving_base else kane.BASE_NONE
        self.forces = np.zeros((1, 6))
        self.base0 = np.zeros((3, 6))          # base pose, rate, acc at t0
        self.t0 = 0.0
        self._args = (params.base_joints, params.platform_joints, params.kernel_data)

    def set_inputs(self, t0, forces, base_pose=None, base_rate=None, base_acc=None):
        """Hold ``forces`` and the base motion given at t0 for the coming step."""
        self.t0 = t0
        self.forces[0] = forces
        if base_pose is not None:
            self.base0[:] = base_pose, base_rate, base_acc
        for name, values in (("leg forces", self.forces), ("base motion", self.base0)):
            if not np.all(np.isfinite(values)):
                raise InvalidInputError(f"{name} input contains NaN or inf")

    def rhs(self, t, x):
        dx, det = kane.rhs(*self._args, x, self.forces, self.base0, self.t0, t, self.base_mode, self.legs)
        self._check_det(det)
        return dx

    def _check_det(self, det):
        if det < SINGULAR_RATIO * self.params.home_det:
            raise SingularConfigurationError(
                f"singular pose reached: |det J| is {det / self.params.home_det:.2e} of home (< {SINGULAR_RATIO})")

    def advance(self, x, h):
        """State at t0 + h from x at t0 (set_inputs first)."""
        x_new = integrators.advance(self.method, self.rhs, self.t0, x, h, self.max_step)
        if np.abs(x_new[:3]).max() > 100.0:
            raise ConvergenceError(f"integrator {self.method} diverged over [{self.t0:.6g}, "
                                   f"{self.t0 + h:.6g}] s: platform more than 100 m away")
        return x_new

    def outputs(self, x):
        """Leg lengths, leg rates and the RPY-angle rates of state x."""
        return kane.leg_state(*self._args, x)
