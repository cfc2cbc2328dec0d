"""FMU: per-leg PID on leg length with model feedforward (controller/).

In doStep(t, h) it reads the reference pose motion, the measured leg lengths and rates,
and the base motion at t, and sets the leg forces the plant will hold over the next
step: one step of delay under a Jacobi master, the delay the gains were designed for.
Default gains come from controller.design at build time (resources/leg_controller_defaults.json),
so instantiating the FMU does not rerun the design.

Disturbance observer (controller/observer.py; off at ``observer_bandwidth`` 0, the default,
which leaves every result bit for bit as it was): from the load cells' ``leg_force_measured``
it estimates the force the legs get from elsewhere (the wind) and subtracts it from the command.
Its model force is the feedforward's (with feedforward none: 0, so it estimates the whole
load); its state is the ``observer_state`` output, saved with the FMU state. Its mass:
``observer_model`` scalar (the default) one ``observer_mass`` for every leg-space mode;
leg_space the model's own leg-space mass matrix at home, shifted to the mean diagonal
``observer_mass`` (with the plant's reflected mass added, the plant's matrix: every mode then
meets its own mass, and the bandwidth is no longer held by the lightest mode's mismatch).

The operating point (``start_force``, all 0 by default: off): the leg forces the plant holds
at the start (a link "@plant.leg_force_actual" to a plant that starts at its equilibrium,
hexapod_plant ``start_equilibrium``). The controller starts commanding them, as a loop that
has been running long would: what its model's feedforward lacks (the mean wind load, the
static load without feedforward) is held by the observer's estimate when it is on, else by
the PID's integral, so neither has to wind up after a start step.
"""
import json
import pathlib

import numpy as np
from pythonfmu.enums import Fmi2Status

from controller.design import leg_mass_matrix
from controller.feedforward import FEEDFORWARD_MODES, Feedforward
from controller.observer import STATES_PER_LEG, observer_mass_matrix, observer_start, observer_update
from controller.pid import PIDGains, pid_update
from fmu_src.operating_point import BASE_POSE, STATIC_LEG_FORCES
from fmu_src.slave import INPUT, OUTPUT, PARAMETER, POSE_UNITS, GuardedSlave, acc_units, rate_units
from fmu_src.wind_fmu import DEFAULTS as WIND
from plant._kernel import ffi, lib
from plant.errors import InvalidInputError
from plant.hexapod.model import StewartParams

POSE_NAMES = ("x", "y", "z", "roll", "pitch", "yaw")
OBSERVER_MODELS = ("scalar", "leg_space")   # observer_model: controller/c/observer.h mb_observer_mass
DEFAULTS_FILE = "leg_controller_defaults.json"
INPUTS = ("reference_pose", "reference_rate", "reference_acc", "leg_length", "leg_rate", "base_pose",
          "base_rate", "base_acc")


class LegController(GuardedSlave):
    description = ("Hexapod leg controller: PID on leg length + inverse-dynamics feedforward "
                   "(none / fixed-base / moving-base model)")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        defaults = json.loads((pathlib.Path(self.resources) / DEFAULTS_FILE).read_text())
        self.enumeration("feedforward", "model feedforward", FEEDFORWARD_MODES, 2)
        self.gains = self.pid_gains(defaults["gains"], "leg length", f"designed for {defaults['design']}")
        pose_desc = lambda prefix: [f"{prefix} {n}" for n in POSE_NAMES]
        home = StewartParams.paper()
        self.inputs = np.zeros((8, 6))   # all inputs in one array: one NaN/inf check per step
        # start: the operating point (fmu_src/operating_point.py), platform at home, base at rest
        self.inputs[0], self.inputs[3], self.inputs[5] = home.home_pose, home.home_lengths, BASE_POSE
        self.input_rows = tuple(self.inputs)   # the same row views every step: the model keeps their C pointers
        for row, (name, desc, units) in enumerate((
            (INPUTS[0], pose_desc("platform reference, in {B},"), POSE_UNITS),
            ("reference_rate", pose_desc("d/dt reference"), rate_units(POSE_UNITS)),
            ("reference_acc", pose_desc("d2/dt2 reference"), acc_units(POSE_UNITS)),
            ("leg_length", "measured leg length", "m"),
            ("leg_rate", "measured leg rate", "m/s"),
            ("base_pose", pose_desc("base, in {W},"), POSE_UNITS),
            ("base_rate", pose_desc("d/dt base"), rate_units(POSE_UNITS)),
            ("base_acc", pose_desc("d2/dt2 base"), acc_units(POSE_UNITS)),
        )):
            self.vector(name, 6, INPUT, desc, units, values=self.inputs[row])
        self.forces = self.vector("leg_force", 6, OUTPUT, "commanded actuator force, + extends", "N")
        self.integral = self.vector("integral", 6, OUTPUT, "integral of the leg-length error", "m.s")
        self.start_force = self.vector("start_force", 6, PARAMETER, "leg force the plant holds at the start "
                                       "(the operating point: the integral or the observer starts holding what the "
                                       "feedforward lacks); all 0: off, both start at rest", "N",
                                       valid=(-1e6, 1e6))
        self.feedforward_force = self.vector("feedforward_force", 6, OUTPUT, "model feedforward part of leg_force", "N")
        self._wind_variables()
        self._observer_variables()

    def _wind_variables(self):
        """Wind feedforward (plant/c/wind.h mb_wind_feedforward): the drag of the measured wind
        speed, by the controller's own drag model, held by the legs at the reference pose."""
        drag = 0.5 * WIND["air_density"] * WIND["drag_coefficient"] * WIND["drag_area"]
        self.wind = self.parameters((
            ("wind_feedforward", "1", 0.0, "gain of the wind feedforward (0 = off; 1 = the whole predicted drag)",
             (0.0, 2.0)),
            ("wind_drag", "kg/m", drag, "the controller's 0.5 rho Cd A of the subreflector (assumed the Wind "
             "FMU's defaults: 1.225 kg/m3, Cd 1.2, a 6.5 m disc)", (0.0, 1e4)),
            ("wind_moment_arm", "m", WIND["moment_arm"], "the controller's centre of pressure along {B}'s z from "
             "{P}'s origin (assumed 1 m, as the Wind FMU's)", (-50.0, 50.0)),
            ("wind_direction", "rad", WIND["direction"], "the controller's azimuth the wind comes from (assumed "
             "known, e.g. from a vane)", (-2 * np.pi, 2 * np.pi)),
            ("wind_cutoff", "1/s", 0.0, "first-order low-pass of the measured speed, Hz (0 = none): keeps the "
             "gusts the anemometer shares with the disc (design choice)", (0.0, 1e3)),
        ))
        self.wind_speed = 0.0
        self.real("wind_speed", INPUT, "measured along-wind speed (an anemometer); read when wind_feedforward > 0",
                  "m/s")

    def _observer_variables(self):
        """The disturbance observer's parameters, input and outputs (controller/observer.py)."""
        self.leg_mass = leg_mass_matrix(StewartParams.paper())   # the model's, at home (native: LEG_MASS_HOME)
        mass = float(np.trace(self.leg_mass)) / 6
        self.enumeration("observer_model", "disturbance observer: its leg-space mass matrix M_o (the mean diagonal "
                         "observer_mass): scalar = observer_mass I, one mass for every mode (the default, as it "
                         "always was); leg_space = the model's M_leg at home + (observer_mass - its mean "
                         "diagonal) I, every mode its own mass", OBSERVER_MODELS, 0)
        self.observer = self.parameters((
            ("observer_bandwidth", "1/s", 0.0, "disturbance observer: bandwidth of its Q filter (2nd order "
             "Butterworth) [Hz]; 0: off", (0.0, 1e3)),
            ("observer_mass", "kg", mass, "disturbance observer: leg-space mass of one leg it assumes, the "
             "reflected mass included (observer_model leg_space: the mean diagonal of its matrix; M_leg's own "
             "plus the reflected mass is the plant's); default the mean diagonal of M_leg at home, none reflected",
             (0.0, 1e6)),
            ("observer_on_time", "s", 0.0, "disturbance observer: the time it switches on (its filter at rest "
             "until then, nothing subtracted: a switch-on is a step load); 0: on from the start", (0.0, 1e9)),
        ))
        self.force_measured = self.vector("leg_force_measured", 6, INPUT, "leg force from the load cells (for "
                                          "the disturbance observer)", "N", start=STATIC_LEG_FORCES)
        self.disturbance = self.vector("disturbance_estimate", 6, OUTPUT, "disturbance observer: external force "
                                       "on the leg (+ extends), subtracted from the command", "N")
        self.observer_state = self.vector("observer_state", STATES_PER_LEG * 6, OUTPUT,
                                          ["disturbance observer: Q filter state", "disturbance observer: its rate",
                                           "disturbance observer: last length error",
                                           "disturbance observer: length error before it"] * 6,
                                          ("N", "N/s", "m", "m") * 6)

    def initialize(self):
        self.params = StewartParams.paper()
        self.pid = PIDGains(**self.gains)
        self.feedforward_model = Feedforward(self.params, FEEDFORWARD_MODES[self.feedforward])
        self.observer_matrix = observer_mass_matrix(self.observer["observer_mass"], self.leg_mass,
                                                    self.observer_model)
        self.saturated = False
        self._kernel = self.params.kernel.params
        self._wind_out = np.zeros(12)   # predicted wrench, leg forces
        self._wind_ptr = ffi.from_buffer("double[]", self._wind_out)
        self._wind_filtered = self.wind_speed
        self._update(None)

    def step(self, t, h):
        self._update(h, t)
        saturated = bool(np.any(np.abs(self.forces) >= self.pid.force_limit))
        if saturated and not self.saturated:   # say so once per episode: an unstable loop saturates quietly
            self.log(f"leg forces saturated at +-{self.pid.force_limit:g} N at t={t + h:.6g} s "
                     "(legs "
                     f"{', '.join(str(i + 1) for i in np.flatnonzero(np.abs(self.forces) >= self.pid.force_limit))})",
                     Fmi2Status.warning, "logStatusWarning")
        self.saturated = saturated

    def _update(self, h, t=0.0):
        """Forces from the inputs now (a step from ``t``); the integral advances only on a real step."""
        if not np.isfinite(self.inputs).all():
            bad = [n for n, row in zip(INPUTS, self.inputs) if not np.isfinite(row).all()]
            raise InvalidInputError(f"{', '.join(bad)} input contains NaN or inf")
        ref, ref_rate, ref_acc, lengths, rates, *base = self.input_rows
        ff, ref_lengths, ref_rates = self.feedforward_model(ref, ref_rate, ref_acc, *base)
        if self.wind["wind_feedforward"]:
            ff = ff + self._wind_forces(ref, base[0], h)
        if h is None:   # initialization: the feedforward alone, integral untouched, or the operating point
            self.forces[:] = ff
            self.observer_state[:] = observer_start(lengths - ref_lengths)
            if self.start_force.any():
                self._start_holding(ff)
        else:
            command = ff
            if self.observer["observer_bandwidth"] and t >= self.observer["observer_on_time"]:
                command = self._observe(ff, lengths - ref_lengths, h)
            elif self.observer["observer_bandwidth"]:   # not on yet: at rest, its length history kept current
                self.observer_state[:] = observer_start(lengths - ref_lengths)
            self.forces[:], self.integral[:] = pid_update(self.pid, self.integral, ref_lengths - lengths,
                                                          ref_rates - rates, command, h)
        self.feedforward_force[:] = ff

    def _start_holding(self, ff):
        """The operating point: start_force commanded, its part beyond the feedforward held by
        the observer's estimate (on from the start) or the integral (off, or on later);
        controller/c/pid.c clips it."""
        hold = self.start_force - ff
        if self.observer["observer_bandwidth"] and self.observer["observer_on_time"] <= 0:
            self.disturbance[:] = -hold
            self.observer_state[0::STATES_PER_LEG] = -hold
            self.integral[:] = 0.0
        elif self.pid.ki > 0:
            self.integral[:] = hold / self.pid.ki
        else:
            raise InvalidInputError("start_force needs an integral gain ki > 0 (or the observer) to hold "
                                    f"{np.abs(hold).max():.6g} N beyond the feedforward; ki is 0")
        self.forces[:] = np.clip(self.start_force, -self.pid.force_limit, self.pid.force_limit)

    def _wind_forces(self, ref, base_pose, h):
        if not np.isfinite(self.wind_speed):
            raise InvalidInputError("wind_speed input contains NaN or inf")
        w = self.wind
        speed = self.wind_speed
        if w["wind_cutoff"] > 0.0:
            self._wind_filtered = lib.mb_wind_speed_filter(self._wind_filtered, speed, w["wind_cutoff"],
                                                           -1.0 if h is None else h)
            speed = self._wind_filtered
        lib.mb_wind_feedforward(*self._kernel, ffi.from_buffer("double[]", ref), ffi.from_buffer("double[]", base_pose),
                                w["wind_drag"], w["wind_moment_arm"], w["wind_direction"], speed,
                                w["wind_feedforward"], self._wind_ptr, self._wind_ptr + 6)
        return self._wind_out[6:]

    def extra_state(self):
        return self._wind_filtered   # the wind speed filter's state

    def set_extra_state(self, extra):
        self._wind_filtered = extra

    def _observe(self, ff, length_error, h):
        """The feedforward minus the observer's estimate; advances the observer's state."""
        if not np.isfinite(self.force_measured).all():
            raise InvalidInputError("leg_force_measured input contains NaN or inf")
        o = self.observer
        self.disturbance[:], self.observer_state[:] = observer_update(
            o["observer_bandwidth"], self.observer_matrix, self.observer_state, ff - self.force_measured, length_error,
            h)
        return ff - self.disturbance
