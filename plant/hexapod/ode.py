"""The hexapod as a first-order ODE dx/dt = f(t, x), advanced step by step (the FMU's core).

State x = [pose (6), twist (6)]: the pose [x, y, z, roll, pitch, yaw] of {P} in {B} and
the twist u = (v, w) of {P} relative to {B} in {B} (the generalised speeds of Kane's
equations; RPY rates are derived, so the speeds carry no RPY singularity).

Over one step the leg forces are held (zero-order hold) and the base motion is
extrapolated from the step's start by its own rates and accelerations (second-order
Taylor), so a base turning at constant acceleration is followed exactly.

Why the fixed-step methods run in C (plant.hexapod.kernel.HexapodKernel.advance_fixed): the FMU's
budget per communication step is ~10x an empty FMU's doStep (~1.4 µs); RK4 in Python
around the compiled right-hand side costs ~20 µs, one C call a few µs. Inputs and
outputs live in two arrays the caller may share (the FMU maps its variables onto them);
their C pointers are taken once here, so a step copies nothing. "radau" goes through
plant.integrators with the C right-hand side.

The leg actuator (Actuator: force-loop bandwidth, reflected mass, screw friction, force
limit) and an external wrench on the platform are terms of the same C call
(mb_hexapod_advance_actuated); all off, it is advance_fixed bit for bit. With a
bandwidth the six motor forces join the state: x = [pose, twist, motor forces] (18).

With a ``tolerance`` (> 0, rk4 only) the substeps are error-controlled instead of fixed
(mb_hexapod_advance_controlled): RK4 substeps of at most max_step, each accepted when the
embedded third-order estimate of its pose error is within the tolerance, and the force
loop's lag integrated exactly (linear, the command held: an exponential). The screw
friction's steep tanh then costs substeps only where the legs cross zero rate, and only
as many as its error asks for, instead of 0.1 ms substeps everywhere (docs/speed.md).
"""
import math
from dataclasses import astuple, dataclass

import numpy as np

from plant import integrators
from plant.errors import ConvergenceError, InvalidInputError, SingularConfigurationError, WorkBoundError
from plant.hexapod import kernel as kane
from plant.hexapod.model import SINGULAR_RATIO, check_stroke, fidelity_mode, inverse_kinematics, jacobian

# RK4's real-axis stability limit is 2.785: a force loop faster than this per substep diverges
RK4_STABLE_RATE_STEP = 2.5


@dataclass(frozen=True)
class Actuator:
    """The electromechanical leg actuator (motor + ball screw), the same on every leg;
    all zero: ideal (the commanded force appears in the leg at once). Units SI."""

    bandwidth: float = 0.0          # Hz, force loop F/F_cmd = 1 / (1 + s / (2 pi bandwidth)); 0: ideal
    reflected_mass: float = 0.0     # kg, rotor + screw inertia reflected along the leg
    coulomb: float = 0.0            # N, Coulomb friction of the screw
    viscous: float = 0.0            # N s/m, viscous friction of the screw
    friction_velocity: float = 1e-4  # m/s, tanh smoothing of the Coulomb friction
    force_limit: float = 0.0        # N, clip of the command; 0: none

    def __post_init__(self):
        for name in ("bandwidth", "reflected_mass", "coulomb", "viscous", "force_limit"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise InvalidInputError(f"actuator {name} must be finite and >= 0, got {value!r}")
        if not (math.isfinite(self.friction_velocity) and self.friction_velocity > 0):
            raise InvalidInputError(
                f"actuator friction_velocity must be finite and > 0, got {self.friction_velocity!r}"
            )

    @property
    def data(self):
        """The kernel's array (plant/c/hexapod.h MB_ACTUATOR_NDATA)."""
        return np.array(astuple(self), dtype=float)

    @property
    def states(self):
        """State count the actuator adds: the six motor forces when it has a bandwidth."""
        return 6 if self.bandwidth > 0 else 0

    def check_step(self, max_step, method):
        """InvalidInputError if the explicit integrator cannot follow the force loop."""
        rate_step = 2 * math.pi * self.bandwidth * max_step
        if method in ("rk4", "euler") and rate_step > (RK4_STABLE_RATE_STEP if method == "rk4" else 1.0):
            raise InvalidInputError(
                f"actuator bandwidth {self.bandwidth:g} Hz is too fast for {method} at max_step {max_step:g} s "
                f"(2 pi f max_step = {rate_step:.3g}); lower max_step below "
                f"{(RK4_STABLE_RATE_STEP if method == 'rk4' else 1.0) / (2 * math.pi * self.bandwidth):.3g} s")


def check_tolerance(tolerance, method):
    """InvalidInputError unless ``tolerance`` is 0 (fixed substeps) or, with rk4, finite and > 0."""
    if not (math.isfinite(tolerance) and tolerance >= 0):
        raise InvalidInputError(f"tolerance must be finite and >= 0 (0: fixed substeps), got {tolerance!r}")
    if tolerance and method != "rk4":
        raise InvalidInputError(f"tolerance {tolerance:g} (error-controlled substeps) needs integrator rk4, "
                                f"got {method!r}; set tolerance 0 for {method}")


class HexapodODE:
    """The hexapod plant between communication points: hold inputs, advance, read out.

    ``inputs`` (5, 6): leg forces (commanded), base pose, base rate, base acc, platform
    wrench in {B} (held over a step). ``outputs`` (4, 6): leg lengths, leg rates, pose
    rates and the forces the actuators deliver, after the last step. The state x given
    to ``advance`` is (12,) + actuator.states."""

    def __init__(self, params, fidelity="full", moving_base=True, method="rk4", max_step=1e-3,
                 inputs=None, outputs=None, actuator=None, tolerance=0.0):
        if method not in integrators.INTEGRATORS:
            raise InvalidInputError(f"unknown integrator {method!r}; choose one of {integrators.INTEGRATORS}")
        if not max_step > 0:
            raise InvalidInputError(f"max_step must be positive, got {max_step}")
        check_tolerance(tolerance, method)
        self.params, self.method, self.max_step, self.tolerance = params, method, max_step, tolerance
        base_mode, self.legs = fidelity_mode(fidelity)
        self.base_mode = base_mode if moving_base else kane.BASE_NONE
        self.actuator = Actuator() if actuator is None else actuator
        if not tolerance:   # error-controlled substeps take the lag exactly
            self.actuator.check_step(max_step, method)
        self.inputs = np.zeros((5, 6)) if inputs is None else inputs
        self.outputs = np.zeros((4, 6)) if outputs is None else outputs
        self.bounds = params.home_lengths + np.array(params.stroke)[:, None]
        self.t0 = 0.0
        self._kernel = params.kernel
        # the arrays are shared with the caller and written in place: checked, never copied
        self._inputs = kane.pointer(self.inputs, (5, 6), "inputs")
        self._outputs = kane.pointer(self.outputs, (4, 6), "outputs")
        self._actuator_data = self.actuator.data
        self._force = np.zeros(6)   # delivered leg forces of the last rhs (radau's read-out)
        self._actuator = kane.pointer(self._actuator_data, (kane.ACTUATOR_NDATA,), "actuator")
        self._bounds = kane.pointer(self.bounds, (2, 6), "bounds")

    def set_inputs(self, t0, forces, base_pose=0.0, base_rate=0.0, base_acc=0.0, wrench=0.0):
        """Hold ``forces`` (commanded), the base motion given at t0 and the platform wrench
        for the coming step."""
        self.t0 = t0
        for row, values in zip(self.inputs, (forces, base_pose, base_rate, base_acc, wrench)):
            row[:] = values

    def initial_state(self, pose):
        """x at rest at ``pose``, the motor forces (if states) at the held, limited command:
        a loop that starts in equilibrium starts without an actuator transient."""
        x = np.zeros(12 + self.actuator.states)
        x[:6] = pose
        if self.actuator.states:
            limit = self.actuator.force_limit
            x[12:] = np.clip(self.inputs[0], -limit, limit) if limit > 0 else self.inputs[0]
        return x

    def rhs(self, t, x):
        dx = np.empty(len(x))   # scipy's Jacobian differencing passes strided x: the kernel copies it
        wrench = self.inputs[4] if self.inputs[4].any() else None
        det = self._kernel.rhs_actuated(self._actuator_data, x, self.inputs[0], wrench, self.inputs[1:4], self.t0, t,
                                        self.base_mode, self.legs, dx, self._force)
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
        if self.tolerance:
            substeps = 0
            det, status = self._kernel.advance_controlled(self.tolerance, self.max_step, integrators.MAX_SUBSTEPS,
                                                          self._actuator, x, self._inputs, self.t0, h, self.base_mode,
                                                          self.legs, self._bounds, self._outputs)
        else:
            substeps = integrators.substep_count(h, self.max_step)
            det, status = self._kernel.advance_actuated(self.method == "rk4", substeps, self._actuator, x,
                                                        self._inputs, self.t0, h, self.base_mode, self.legs,
                                                        self._bounds, self._outputs)
        if status == kane.OK and det >= SINGULAR_RATIO * self.params.home_det:
            return self.outputs
        if status == kane.BAD_INPUT:
            names = ("leg forces", "base pose", "base rate", "base acc", "platform wrench")
            bad = [n for n, row in zip(names, self.inputs) if not np.isfinite(row).all()]
            raise InvalidInputError(f"{', '.join(bad)} input contains NaN or inf")
        if status == kane.WORK:
            raise WorkBoundError(f"a step of {h!r} s needs more than {integrators.MAX_SUBSTEPS} substeps to keep "
                                 f"the pose error per substep within tolerance {self.tolerance!r}: take a larger "
                                 "tolerance or shorter communication steps")
        if status == kane.DIVERGED:
            substep = f"{h / substeps:.3g} s" if substeps else f"error-controlled, tolerance {self.tolerance:g}"
            raise ConvergenceError(f"integrator {self.method} diverged over [{self.t0:.6g}, {self.t0 + h:.6g}] s "
                                   f"(substep {substep}): the state is no longer finite or bounded")
        self._check_det(det)
        check_stroke(self.params, self.outputs[0])
        return self.outputs

    def _advance_radau(self, x, h):
        if not np.isfinite(self.inputs).all():
            raise InvalidInputError("an input (leg forces or base motion) contains NaN or inf")
        if h > 0:
            x[:] = integrators.advance("radau", self.rhs, self.t0, x, h, self.max_step)
        self.outputs[0] = inverse_kinematics(self.params, x[:6])
        self.outputs[1] = jacobian(self.params, x[:6]) @ x[6:12]
        self.outputs[2] = self.rhs(self.t0 + h, x)[:6]
        self.outputs[3] = self._force
        check_stroke(self.params, self.outputs[0])
        return self.outputs
