"""FMU: the 3T parallel mechanism of Shen et al. 2024 ("mechanism 1"), slider forces in,
slider and platform motion out.

The physics is plant.mechanism3t.model; this file maps FMI variables onto it. State: the slider
positions rho = (x_A2, y_A1, y_A3) and rates; dynamics M(rho) rho_ddot = F - bias(rho, rho_dot)
(plant.mechanism3t.model.forward_dynamics: the virtual-work model of slider_forces, solved for the
accelerations), evaluated by its compiled single-state kernel plant.mechanism3t.kernel
(same numbers to ~1e-15 relative, ~2 µs instead of ~420 µs a state). Over a communication
step the forces are held and the state is advanced with the chosen method: RK4 and Euler
by the kernel's compiled advance_fixed (plant.integrators.rk4/euler's arithmetic and
substeps, without their per-stage numpy overhead), Radau by plant.integrators.advance on
the compiled right-hand side; O' follows from forward_branch in the chosen assembly mode
(compiled too). The state lives in the output arrays (views of one state vector), so
get/set FMU state restores it.

Default max_step 5 ms: held forces leave only the open-loop dynamics inside a step (gravity
mode 7.4 rad/s, swing 9.8 rad/s at the paper configuration), where RK4 at 5 ms is within
~1e-9 m of Radau over 0.5 s; co-simulation steps up to 5 ms then cost one substep.

Errors (each a plant.errors.PlantError, reported by GuardedSlave as fmi2Discard with the
message logged): NaN/inf forces (InvalidInputError), a configuration with no assembly in
the chosen mode (UnreachableError, also for unreachable initial positions), an output
singularity or a stretched passive limb (SingularConfigurationError), a non-finite state
(ConvergenceError).
"""

import numpy as np

from fmu_src.operating_point import STATIC_SLIDER_FORCES
from fmu_src.slave import INPUT, OUTPUT, PARAMETER, POSITIVE_TIME, GuardedSlave
from plant.errors import ConvergenceError, InvalidInputError
from plant.integrators import INTEGRATORS, advance, substep_count
from plant.mechanism3t import kernel
from plant.mechanism3t.model import MM, PAPER_REFERENCE_RHO_MM, Mechanism3TParams, _check_mode

SLIDERS = ("x_A2", "y_A1", "y_A3")
AXES = ("x", "y", "z")
# the sliders' actuator ranges (paper 3.4); rates up to 1 m/s (assumed: a screw-driven slider)
POSITION_RANGE = list(zip(Mechanism3TParams.paper().rho_min, Mechanism3TParams.paper().rho_max))
RATE_RANGE = (-1.0, 1.0)


class Mechanism3TPlant(GuardedSlave):
    description = ("3T decoupled parallel mechanism (Shen et al. 2024, mechanism 1), virtual-work dynamics in slider "
                   "coordinates")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.enumeration("integrator", "integrator", INTEGRATORS, 0)
        self.integer("mode", "assembly mode, +1 or -1: sign before the square root of eq. 11 (paper check: +1)", 1,
                     (-1, 1), allowed=(-1, 1))
        self.max_step = 5e-3
        self.real("max_step", PARAMETER, "largest internal integration step; > 0", "s", self.max_step,
                  valid=(POSITIVE_TIME, None))
        rho0 = np.array(PAPER_REFERENCE_RHO_MM) * MM
        self.initial_position = self.vector("initial_position", 3, PARAMETER,
                                            [f"initial slider position {s}" for s in SLIDERS], "m", rho0,
                                            valid=POSITION_RANGE)
        self.initial_rate = self.vector("initial_rate", 3, PARAMETER,
                                        [f"initial slider rate d/dt {s}" for s in SLIDERS], "m/s",
                                        valid=RATE_RANGE)
        self.force = self.vector("slider_force", 3, INPUT,
                                 ["actuator force on slider x_A2 along +x", "actuator force on slider y_A1 along +y",
                                  "actuator force on slider y_A3 along +y"], "N",
                                 start=STATIC_SLIDER_FORCES)   # holding it still at rho0 (operating point)
        self.x = np.r_[rho0, np.zeros(3)]
        self.vector("slider_position", 3, OUTPUT, [f"slider position {s}" for s in SLIDERS], "m",
                    values=self.x[:3])
        self.vector("slider_rate", 3, OUTPUT, [f"slider rate d/dt {s}" for s in SLIDERS], "m/s",
                    values=self.x[3:])
        self.params = Mechanism3TParams.paper()
        self.packed = kernel.pack(self.params)
        self.platform = self.vector("platform_position", 3, OUTPUT,
                                    [f"moving platform centre O' {a} in frame O" for a in AXES], "m",
                                    kernel.forward_branch(self.packed, rho0))
        self.method = INTEGRATORS[0]

    def initialize(self):
        if not 0 <= self.integrator < len(INTEGRATORS):
            raise InvalidInputError(f"integrator index {self.integrator} is not one of 0..{len(INTEGRATORS) - 1} "
                                    f"({', '.join(INTEGRATORS)})")
        if not self.max_step > 0:
            raise InvalidInputError(f"max_step must be positive, got {self.max_step}")
        self.method = INTEGRATORS[self.integrator]
        _check_mode(self.mode)
        self.x[:] = np.r_[self.initial_position, self.initial_rate]
        self._update_platform()
        self._rhs(0.0, self.x)   # refuses singular starts and NaN forces now, not at the first step

    def _rhs(self, t, x):
        status, xdot = kernel.rhs_kernel(self.packed, x, self.force, self.mode)
        kernel.raise_status(status, self.mode)
        return xdot

    def _update_platform(self):
        p = np.empty(3)
        kernel.raise_status(kernel.position_kernel(self.packed, self.x[:3], self.mode, p), self.mode)
        self.platform[:] = p

    def step(self, t, h):
        if self.method == "radau":
            self.x[:] = advance(self.method, self._rhs, t, self.x, h, self.max_step)
        else:   # plant.integrators._substeps and advance's divergence check, compiled stages
            n = substep_count(h, self.max_step)
            status, x = kernel.advance_fixed(self.packed, self.x, self.force, self.mode, self.method == "rk4", n, h / n)
            kernel.raise_status(status, self.mode)
            if not np.all(np.isfinite(x)):
                raise ConvergenceError(f"integrator {self.method} diverged over [{t:.6g}, {t + h:.6g}] s "
                                       f"(substep {min(h, self.max_step):.3g} s): state is no longer finite")
            self.x[:] = x
        self._update_platform()
