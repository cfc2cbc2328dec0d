"""FMU: the 6-UPS hexapod plant (seed 000), leg forces in, leg and platform motion out.

The physics is plant.hexapod_ode / plant.stewart; this file maps FMI variables onto it.
Over a communication step the leg forces are held and the base motion is extrapolated
by its rates and accelerations; the state survives get/set FMU state.
"""
import numpy as np

from fmu_src.slave import (INPUT, OUTPUT, PARAMETER, POSE_UNITS, GuardedSlave, acc_units,
                           rate_units)
from plant.hexapod_ode import HexapodODE
from plant.integrators import INTEGRATORS
from plant.stewart import FIDELITIES, HOME_POSE, StewartParams, check_stroke

POSE_NAMES = ("x", "y", "z", "roll", "pitch", "yaw")


class HexapodPlant(GuardedSlave):
    description = "6-UPS subreflector hexapod (Yao et al. 2018), Kane dynamics, fixed or moving base"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.integer("moving_base", "1: the base moves as the base_* inputs say; 0: fixed base (inputs ignored)", 1)
        self.integer("fidelity", "model fidelity: " + ", ".join(f"{i} {f}" for i, f in enumerate(FIDELITIES)), 0)
        self.integer("integrator", "integrator: " + ", ".join(f"{i} {m}" for i, m in enumerate(INTEGRATORS)), 0)
        self.max_step = 1e-3
        self.stroke = 0.15
        self.real("max_step", PARAMETER, "largest internal integration step", "s", self.max_step)
        self.real("stroke", PARAMETER, "half stroke of every leg about its home length (assumed)", "m", self.stroke)
        self.initial_pose = self.vector("initial_pose", 6, PARAMETER,
                                        [f"initial platform {n} in {{B}}" for n in POSE_NAMES], POSE_UNITS,
                                        HOME_POSE)
        self.forces = self.vector("leg_force", 6, INPUT, "actuator force along the leg, + extends", "N")
        self.base_pose = self.vector("base_pose", 6, INPUT, [f"base {n} in {{W}}" for n in POSE_NAMES], POSE_UNITS)
        self.base_rate = self.vector("base_rate", 6, INPUT, [f"d/dt base {n}" for n in POSE_NAMES],
                                     rate_units(POSE_UNITS))
        self.base_acc = self.vector("base_acc", 6, INPUT, [f"d2/dt2 base {n}" for n in POSE_NAMES],
                                    acc_units(POSE_UNITS))
        self.lengths = self.vector("leg_length", 6, OUTPUT, "leg length B_i to a_i", "m",
                                   StewartParams.paper().home_lengths)
        self.leg_rates = self.vector("leg_rate", 6, OUTPUT, "leg extension rate", "m/s")
        self.pose = self.vector("pose", 6, OUTPUT, [f"platform {n} in {{B}}" for n in POSE_NAMES], POSE_UNITS,
                                HOME_POSE)
        self.pose_rate = self.vector("pose_rate", 6, OUTPUT, [f"d/dt platform {n}" for n in POSE_NAMES],
                                     rate_units(POSE_UNITS))
        self.x = np.zeros(12)
        self.ode = None

    def initialize(self):
        self.params = StewartParams.paper(stroke=(-self.stroke, self.stroke))
        self.ode = HexapodODE(self.params, FIDELITIES[self.fidelity], bool(self.moving_base),
                              INTEGRATORS[self.integrator], self.max_step)
        self.x[:] = np.r_[self.initial_pose, np.zeros(6)]
        self._publish()

    def step(self, t, h):
        if self.moving_base:
            self.ode.set_inputs(t, self.forces, self.base_pose, self.base_rate, self.base_acc)
        else:
            self.ode.set_inputs(t, self.forces)
        self.x[:] = self.ode.advance(self.x, h)
        self._publish()

    def _publish(self):
        lengths, rates, rpy_rates = self.ode.outputs(self.x)
        check_stroke(self.params, lengths)
        self.lengths[:], self.leg_rates[:] = lengths, rates
        self.pose[:] = self.x[:6]
        self.pose_rate[:3], self.pose_rate[3:] = self.x[6:9], rpy_rates

    def extra_state(self):
        return self.x.copy()

    def set_extra_state(self, extra):
        self.x[:] = extra
