"""FMU: per-leg PID on leg length with model feedforward (controller/).

In doStep(t, h) it reads the reference pose motion, the measured leg lengths and rates,
and the base motion at t, and sets the leg forces the plant will hold over the next
step: one step of delay under a Jacobi master, the delay the gains were designed for.
Default gains come from controller.design at build time (resources/leg_controller_defaults.json),
so instantiating the FMU does not rerun the design.
"""
import json
import pathlib

import numpy as np

from controller.feedforward import FEEDFORWARD_MODES, feedforward_and_legs
from controller.pid import PIDGains, pid_step
from fmu_src.slave import INPUT, OUTPUT, PARAMETER, POSE_UNITS, GuardedSlave, acc_units, rate_units
from plant.stewart import StewartParams

POSE_NAMES = ("x", "y", "z", "roll", "pitch", "yaw")
DEFAULTS_FILE = "leg_controller_defaults.json"


class LegController(GuardedSlave):
    description = "Hexapod leg controller: PID on leg length + inverse-dynamics feedforward (none / fixed-base / moving-base model)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        defaults = json.loads((pathlib.Path(self.resources) / DEFAULTS_FILE).read_text())
        self.integer("feedforward", "model feedforward: " + ", ".join(
            f"{i} {m}" for i, m in enumerate(FEEDFORWARD_MODES)), 2)
        self.gains = dict(defaults["gains"])
        design = defaults["design"]
        for name, unit, text in (
            ("kp", "N/m", "proportional gain on leg length"),
            ("ki", "N/(m.s)", "integral gain on leg length"),
            ("kd", "N.s/m", "derivative gain on leg rate"),
            ("force_limit", "N", "actuator force saturation per leg (assumed)"),
        ):
            self.real(name, PARAMETER, f"{text}; default designed for {design}", unit, self.gains[name],
                      getter=lambda n=name: self.gains[n], setter=lambda v, n=name: self.gains.__setitem__(n, v))
        pose_desc = lambda prefix: [f"{prefix} {n}" for n in POSE_NAMES]
        self.ref = self.vector("reference_pose", 6, INPUT, pose_desc("platform reference, in {B},"), POSE_UNITS,
                               StewartParams.paper().home_pose)
        self.ref_rate = self.vector("reference_rate", 6, INPUT, pose_desc("d/dt reference"), rate_units(POSE_UNITS))
        self.ref_acc = self.vector("reference_acc", 6, INPUT, pose_desc("d2/dt2 reference"), acc_units(POSE_UNITS))
        self.lengths = self.vector("leg_length", 6, INPUT, "measured leg length", "m",
                                   StewartParams.paper().home_lengths)
        self.rates = self.vector("leg_rate", 6, INPUT, "measured leg rate", "m/s")
        self.base_pose = self.vector("base_pose", 6, INPUT, pose_desc("base, in {W},"), POSE_UNITS)
        self.base_rate = self.vector("base_rate", 6, INPUT, pose_desc("d/dt base"), rate_units(POSE_UNITS))
        self.base_acc = self.vector("base_acc", 6, INPUT, pose_desc("d2/dt2 base"), acc_units(POSE_UNITS))
        self.forces = self.vector("leg_force", 6, OUTPUT, "commanded actuator force, + extends", "N")
        self.integral = self.vector("integral", 6, OUTPUT, "integral of the leg-length error", "m.s")
        self.feedforward_force = self.vector("feedforward_force", 6, OUTPUT, "model feedforward part of leg_force", "N")

    def initialize(self):
        self.params = StewartParams.paper()
        self.pid = PIDGains(**self.gains)
        self.mode = FEEDFORWARD_MODES[self.feedforward]
        self._update(None)

    def step(self, t, h):
        self._update(h)

    def _update(self, h):
        """Forces from the inputs now; the integral advances only on a real step."""
        ff, ref_lengths, ref_rates = feedforward_and_legs(self.params, self.mode, self.ref, self.ref_rate,
                                                          self.ref_acc, self.base_pose, self.base_rate,
                                                          self.base_acc)
        if h is None:   # initialization: the feedforward alone, integral untouched
            self.forces[:] = ff
        else:
            self.forces[:], self.integral[:] = pid_step(self.pid, self.integral, ref_lengths, ref_rates,
                                                        self.lengths, self.rates, ff, h)
        self.feedforward_force[:] = ff
