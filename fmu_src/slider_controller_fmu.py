"""FMU: slider controller of the 3T mechanism: the paper's reference motion, per-slider PID
(controller.pid) and model feedforward (plant.mechanism3t.model.slider_forces of the reference,
evaluated per step by the compiled single-state kernel plant.mechanism3t.kernel as
M rho_ddot + bias: the same numbers to ~1e-15 relative, ~3 µs instead of ~420 µs).

Reference (paper 4.3): every slider follows initial_position + amplitude sin(omega t),
10 mm and 0.5 rad/s by default (plant.mechanism3t.model.paper_motion). In doStep(t, h) it reads
the measured slider positions and rates at t and sets the forces, reference and
feedforward at t; the plant holds those forces over the next step: one step of delay
under a Jacobi master, the delay the gains were checked for. In initialization the
forces are the feedforward alone (the integral starts at zero).

Default gains (constants below, no design at instantiate time). The loop in slider
space is PID(s) M^-1 / s^2 plus gravity, M the generalised mass matrix
(plant.mechanism3t.model.mass_matrix). At the paper configuration M has eigen-masses 12.5,
36.7 and 50.8 kg (within 2 % over the +-10 mm motion, 5 % for the heaviest); with the
same PID on every slider the loop decouples in M's eigenvectors (as in
controller.design), so the gains were set with controller.design.leg_loop (ZOH plant,
sampled position and rate, one step of delay) at h = 1 ms: crossover 3 Hz with 60 deg
phase margin on the heaviest mode, integral zero a factor 10 below crossover
(ki = kp w_c / 10), then rounded. Modal margins at h = 1 ms: crossover 3.0 / 4.0 / 11.4 Hz,
phase margin 60 / 66 / 76 deg, gain margin >= 23 dB; closed-loop -3 dB bandwidth
4.2 Hz (heaviest mode) to 14.5 Hz (lightest). Why a factor 10 and not 5 (the hexapod's):
gravity makes the open-loop mechanism unstable (real pole at 7.4 rad/s = 1.2 Hz, from
linearising forward_dynamics), which the modal design ignores; in the linearised MIMO loop
with gravity, coupling, ZOH and delay the factor 5 leaves a pole pair at zeta = 0.37,
the factor 10 gives zeta >= 0.77 for every closed-loop pole at h = 1-2 ms (0.69 at 5 ms,
0.15 at 10 ms: do not run these gains above ~5 ms). A 2 Hz crossover leaves zeta 0.07
(too close to the gravity pole); 4-6 Hz buys little for a 0.08 Hz reference whose forces
the feedforward carries, and loses damping at 5 ms. tests/fmu_src/test_python_fmus_mechanism3t.py
repeats the modal and MIMO checks.

The force limit 1 kN per slider is an assumption (the paper gives no actuator rating):
about 6x the largest force of the paper example (173.5 N on x_A2 in this model).
"""
import numpy as np
from pythonfmu.enums import Fmi2Status

from controller.pid import PIDGains, pid_update
from fmu_src.mechanism3t_plant_fmu import POSITION_RANGE
from fmu_src.slave import INPUT, OUTPUT, PARAMETER, GuardedSlave
from plant.errors import InvalidInputError
from plant.mechanism3t import kernel
from plant.mechanism3t.model import MM, PAPER_REFERENCE_RHO_MM, Mechanism3TParams, paper_motion

SLIDERS = ("x_A2", "y_A1", "y_A3")
DEFAULT_GAINS = {"kp": 8.6e3, "ki": 1.6e4, "kd": 890.0, "force_limit": 1e3}
DESIGN = "heaviest slider mode (50.8 kg) 3 Hz crossover, 60 deg phase margin at h = 1 ms"


class SliderController(GuardedSlave):
    description = "3T mechanism slider controller: paper 4.3 sine reference, per-slider PID + virtual-work feedforward"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.enumeration("feedforward", "model feedforward of the reference motion", ("off", "on"), 1)
        self.integer("mode", "assembly mode of the feedforward model, +1 or -1 (paper check: +1)", 1,
                     (-1, 1), allowed=(-1, 1))
        self.amplitude, self.omega = 0.010, 0.5
        self.real("amplitude", PARAMETER, "amplitude of every slider's sine reference", "m", self.amplitude,
                  valid=(0.0, None))
        self.real("omega", PARAMETER, "angular frequency of the sine reference", "rad/s", self.omega,
                  valid=(0.0, None))
        rho0 = np.array(PAPER_REFERENCE_RHO_MM) * MM
        self.initial_position = self.vector("initial_position", 3, PARAMETER,
                                            [f"centre of the reference of slider {s}" for s in SLIDERS], "m", rho0,
                                            valid=POSITION_RANGE)
        self.gains = self.pid_gains(DEFAULT_GAINS, "slider position", DESIGN)
        self.measured = np.zeros((2, 3))
        self.measured[0] = rho0
        self.vector("slider_position", 3, INPUT, [f"measured slider position {s}" for s in SLIDERS], "m",
                    values=self.measured[0])
        self.vector("slider_rate", 3, INPUT, [f"measured slider rate d/dt {s}" for s in SLIDERS], "m/s",
                    values=self.measured[1])
        self.params = Mechanism3TParams.paper()
        self.packed = kernel.pack(self.params)
        ff0 = kernel.slider_forces(self.packed, *paper_motion(0.0, rho0, self.amplitude, self.omega))
        self.forces = self.vector("slider_force", 3, OUTPUT,
                                  [f"commanded force on slider {s} (+x for x_A2, +y for y_A1, y_A3)" for s in SLIDERS],
                                  "N", ff0)
        self.reference = self.vector("reference_position", 3, OUTPUT,
                                     [f"reference position of slider {s}" for s in SLIDERS], "m", rho0)
        self.reference_rate = self.vector("reference_rate", 3, OUTPUT,
                                          [f"reference rate of slider {s}" for s in SLIDERS], "m/s",
                                          np.full(3, self.amplitude * self.omega))
        self.feedforward_force = self.vector("feedforward_force", 3, OUTPUT,
                                             [f"model feedforward part of the force on slider {s}" for s in SLIDERS],
                                             "N", ff0)
        self.integral = self.vector("integral", 3, OUTPUT,
                                    [f"integral of the position error of slider {s}" for s in SLIDERS], "m.s")
        self.start_time = 0.0
        self.pid = None

    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        self.start_time = start_time

    def initialize(self):
        if self.feedforward not in (0, 1):
            raise InvalidInputError(f"feedforward must be 0 (off) or 1 (on), got {self.feedforward}")
        self.pid = PIDGains(**self.gains)
        self.integral[:] = 0.0
        self.saturated = False
        self._update(self.start_time, None)

    def step(self, t, h):
        self._update(t, h)
        at_limit = np.flatnonzero(np.abs(self.forces) >= self.pid.force_limit)
        if len(at_limit) and not self.saturated:   # once per episode, as the leg controller says it
            self.log(f"slider forces saturated at +-{self.pid.force_limit:g} N at t={t + h:.6g} s "
                     f"(sliders {', '.join(SLIDERS[k] for k in at_limit)})", Fmi2Status.warning, "logStatusWarning")
        self.saturated = bool(len(at_limit))

    def _update(self, t, h):
        """Reference, feedforward and forces at t; the integral advances only on a real step."""
        ref, ref_rate, ref_acc = paper_motion(t, self.initial_position, self.amplitude, self.omega)
        ff = kernel.slider_forces(self.packed, ref, ref_rate, ref_acc, self.mode) if self.feedforward else np.zeros(3)
        if h is None:
            self.forces[:] = np.clip(ff, -self.pid.force_limit, self.pid.force_limit)
        else:
            if not np.isfinite(self.measured).all():
                raise InvalidInputError(f"measured slider position/rate input contains NaN or inf: {self.measured}")
            if not (np.isfinite(h) and h > 0):
                raise ValueError(f"time step must be finite and > 0, got {h}")
            # controller.pid.pid_step without its per-argument checks (done above)
            self.forces[:], self.integral[:] = pid_update(self.pid, self.integral, ref - self.measured[0],
                                                          ref_rate - self.measured[1], ff, h)
        self.reference[:], self.reference_rate[:], self.feedforward_force[:] = ref, ref_rate, ff
