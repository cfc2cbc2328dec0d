"""FMU: the 6-UPS hexapod plant (seed 000), leg forces in, leg and platform motion out.

The physics is plant.hexapod_ode / plant.stewart; this file maps FMI variables onto it.
Over a communication step the leg forces are held and the base motion is extrapolated
by its rates and accelerations (with moving_base = 0 the base inputs are ignored); the
FMU variables are views of the ODE's input/output arrays, so a step copies nothing.
The state survives get/set FMU state.
"""
import numpy as np

from fmu_src.slave import (INPUT, OUTPUT, PARAMETER, POSE_UNITS, POSITIVE_TIME, GuardedSlave, acc_units,
                           rate_units)
from plant.hexapod_ode import HexapodODE
from plant.integrators import INTEGRATORS
from plant.stewart import FIDELITIES, HOME_POSE, StewartParams

POSE_NAMES = ("x", "y", "z", "roll", "pitch", "yaw")
# half stroke: from 1 mm (less stops a run at the first mm of motion; no actuator has
# less travel) to the shortest home leg length (more leaves a negative lowest length)
STROKE_RANGE = (1e-3, float(StewartParams.paper().home_lengths.min()))


class HexapodPlant(GuardedSlave):
    description = "6-UPS subreflector hexapod (Yao et al. 2018), Kane dynamics, fixed or moving base"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.integer("moving_base", "1: the base moves as the base_* inputs say; 0: fixed base (inputs ignored)", 1,
                     (0, 1))
        self.enumeration("fidelity", "model fidelity", FIDELITIES, 0)
        self.enumeration("integrator", "integrator", INTEGRATORS, 0)
        self.max_step = 1e-3
        self.stroke = 0.15
        self.real("max_step", PARAMETER, "largest internal integration step; > 0", "s", self.max_step,
                  valid=(POSITIVE_TIME, None))
        self.real("stroke", PARAMETER, "half stroke of every leg about its home length (assumed)", "m", self.stroke,
                  valid=STROKE_RANGE)
        self.initial_pose = self.vector("initial_pose", 6, PARAMETER,
                                        [f"initial platform {n} in {{B}}" for n in POSE_NAMES], POSE_UNITS,
                                        HOME_POSE)
        self.inputs, self.outputs = np.zeros((4, 6)), np.zeros((3, 6))   # shared with the ODE
        self.vector("leg_force", 6, INPUT, "actuator force along the leg, + extends", "N", values=self.inputs[0])
        self.vector("base_pose", 6, INPUT, [f"base {n} in {{W}}" for n in POSE_NAMES], POSE_UNITS,
                    values=self.inputs[1])
        self.vector("base_rate", 6, INPUT, [f"d/dt base {n}" for n in POSE_NAMES], rate_units(POSE_UNITS),
                    values=self.inputs[2])
        self.vector("base_acc", 6, INPUT, [f"d2/dt2 base {n}" for n in POSE_NAMES], acc_units(POSE_UNITS),
                    values=self.inputs[3])
        self.outputs[0] = StewartParams.paper().home_lengths
        self.vector("leg_length", 6, OUTPUT, "leg length B_i to a_i", "m", values=self.outputs[0])
        self.vector("leg_rate", 6, OUTPUT, "leg extension rate", "m/s", values=self.outputs[1])
        self.vector("pose_rate", 6, OUTPUT, [f"d/dt platform {n}" for n in POSE_NAMES], rate_units(POSE_UNITS),
                    values=self.outputs[2])
        self.x = np.r_[HOME_POSE, np.zeros(6)]
        self.vector("pose", 6, OUTPUT, [f"platform {n} in {{B}}" for n in POSE_NAMES], POSE_UNITS,
                    values=self.x[:6])
        self.ode = None

    def initialize(self):
        params = StewartParams.paper(stroke=(-self.stroke, self.stroke))
        self.ode = HexapodODE(params, FIDELITIES[self.fidelity], bool(self.moving_base),
                              INTEGRATORS[self.integrator], self.max_step, self.inputs, self.outputs)
        self.x[:] = np.r_[self.initial_pose, np.zeros(6)]
        self.ode.advance(self.x, 0.0)

    def step(self, t, h):
        self.ode.t0 = t
        self.ode.advance(self.x, h)

    def extra_state(self):
        return self.x.copy()

    def set_extra_state(self, extra):
        self.x[:] = extra
