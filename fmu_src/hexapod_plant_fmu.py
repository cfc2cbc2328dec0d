"""FMU: the 6-UPS hexapod plant (seed 000), leg forces in, leg and platform motion out.

The physics is plant.hexapod.ode / plant.hexapod.model; this file maps FMI variables onto it.
Over a communication step the leg forces are held and the base motion is extrapolated
by its rates and accelerations (with moving_base = 0 the base inputs are ignored); the
FMU variables are views of the ODE's input/output arrays, so a step copies nothing.
The state survives get/set FMU state.

The leg actuator (plant.hexapod.ode.Actuator) is off by default: the commanded force
appears in the leg at once, as before. Its defaults are 0 (off), not a real screw's
values; the realistic scenario (scenarios/files/telescope_slew_realistic.toml) sets them,
with their sources. With a bandwidth the six motor forces are states, saved with the FMU
state; they start at the commanded force at initialization (no start transient).
With ``start_equilibrium`` 1 the leg_force input is first set to the forces that hold the
platform still at its initial pose against its inputs at initialization (the base's motion,
the platform wrench: the mean wind load of a run that has been going on), so a loop whose
controller also starts there (leg_controller ``start_force``) begins at its operating point.

The inputs start at the kit's operating point (fmu_src/operating_point.py): the base at
the telescope's default start pointing, at rest, and the leg forces that hold the
platform still at home there, so a host that steps before setting any input (a plain
fmpy.simulate_fmu) sees the platform stay put instead of falling out of its stroke.
"""
import numpy as np

from fmu_src.operating_point import BASE_POSE, STATIC_LEG_FORCES
from fmu_src.slave import INPUT, OUTPUT, PARAMETER, POSE_UNITS, POSITIVE_TIME, GuardedSlave, acc_units, rate_units
from plant.hexapod import kernel as kane
from plant.hexapod.model import FIDELITIES, HOME_POSE, StewartParams, check_body
from plant.hexapod.ode import Actuator, HexapodODE
from plant.integrators import INTEGRATORS

POSE_NAMES = ("x", "y", "z", "roll", "pitch", "yaw")
# error-controlled substeps' pose error per substep: up to 1 mm (more is no control of a
# hexapod whose stroke is ~0.1 m); 0 is fixed substeps
TOLERANCE_RANGE = (0.0, 1e-3)
# half stroke: from 1 mm (less stops a run at the first mm of motion; no actuator has
# less travel) to the shortest home leg length (more leaves a negative lowest length)
STROKE_RANGE = (1e-3, float(StewartParams.paper().home_lengths.min()))
# initial pose: within the largest stroke of home in translation, tilts within +-90 deg
# (a wider range no hexapod reaches; the kernel refuses what its legs cannot hold)
POSE_RANGE = [(h - STROKE_RANGE[1], h + STROKE_RANGE[1]) for h in HOME_POSE[:3]] + [(-np.pi / 2, np.pi / 2)] * 3
# A model that is wrong: the payload (platform + subreflector) as built, against the
# paper's values the controller's feedforward knows; +-50 % of them (a wider error is a
# different payload, not a tolerance). Its centre of mass may sit off o_P, where the model
# puts it, by up to 0.5 m along each axis (a third of the joint circle's radius; more is a
# different payload).
_PAPER = StewartParams.paper()
PAYLOAD_MASS_RANGE = (-0.5 * _PAPER.platform_mass, 0.5 * _PAPER.platform_mass)
PAYLOAD_INERTIA_RANGE = [(-0.5 * i, 0.5 * i) for i in _PAPER.platform_inertia]
PAYLOAD_COM_RANGE = [(-0.5, 0.5)] * 3


def holding_forces(params, base_mode, legs, pose, inputs):
    """The leg forces [N] (6,) that hold the platform still at ``pose`` on the base motion
    and against the wrench of ``inputs`` (4, 6): base pose, rate, acc, platform wrench
    (plant/c/hexapod.h mb_hexapod_kane_ext, inverse dynamics at zero pose rate and
    acceleration; the native FMU makes the same call)."""
    one = lambda a: np.ascontiguousarray(np.reshape(a, (1, 6)), dtype=float)
    zero = np.zeros((1, 6))
    M, J = np.empty((1, 6, 6)), np.empty((1, 6, 6))
    h, ldot, length, out = (np.empty((1, 6)) for _ in range(4))
    kane.kane(params.base_joints, params.platform_joints, params.kernel_data, one(pose), zero, zero, one(inputs[0]),
              one(inputs[1]), one(inputs[2]), base_mode, legs, False, kane.ID, M, h, J, ldot, length, out,
              np.empty(1), wrench=one(inputs[3]))
    return out[0]


class HexapodPlant(GuardedSlave):
    description = "6-UPS subreflector hexapod (Yao et al. 2018), Kane dynamics, fixed or moving base"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.integer("moving_base", "1: the base moves as the base_* inputs say; 0: fixed base (inputs ignored)", 1,
                     (0, 1))
        self.enumeration("fidelity", "model fidelity", FIDELITIES, 0)
        self.integer("start_equilibrium", "1: the leg_force input (and the motor forces) start at the forces "
                     "that hold the platform still at initial_pose against the base motion and platform wrench "
                     "given at initialization (the operating point); 0: at the leg_force input", 0, (0, 1))
        self.enumeration("integrator", "integrator", INTEGRATORS, 0)
        self.max_step = 1e-3
        self.stroke = 0.15
        self.real("max_step", PARAMETER, "largest internal integration step; > 0", "s", self.max_step,
                  valid=(POSITIVE_TIME, None))
        self.tolerance = 0.0
        self.real("tolerance", PARAMETER, "rk4 only: error-controlled substeps of at most max_step, each one's "
                  "pose error (m, rad) at most this, the actuator lag exact; 0: fixed substeps of max_step", "m",
                  self.tolerance, valid=TOLERANCE_RANGE)
        self.real("stroke", PARAMETER, "half stroke of every leg about its home length (assumed)", "m", self.stroke,
                  valid=STROKE_RANGE)
        self.actuator = self.parameters((
            ("actuator_bandwidth", "1/s", 0.0, "leg force-loop bandwidth, F/F_cmd = 1/(1 + s/(2 pi f)); 0: ideal "
             "(the force appears at once)", (0.0, 1e4)),
            ("reflected_mass", "kg", 0.0, "motor rotor + screw inertia reflected along each leg, "
             "J (2 pi / pitch)^2; 0: none", (0.0, 1e5)),
            ("coulomb_friction", "N", 0.0, "Coulomb friction of each leg's screw; 0: none", (0.0, 1e5)),
            ("viscous_friction", "N.s/m", 0.0, "viscous friction of each leg's screw; 0: none", (0.0, 1e7)),
            ("friction_velocity", "m/s", 1e-4, "tanh smoothing velocity of the Coulomb friction; > 0",
             (1e-9, 1.0)),
            ("actuator_force_limit", "N", 0.0, "motor force limit (the command is clipped to +-limit); 0: none",
             (0.0, None)),
        ))
        self.payload = self.parameters((
            ("payload_mass_error", "kg", 0.0, f"the payload's mass minus the {_PAPER.platform_mass} kg the "
             "controller's model knows (assumed: rigid with the platform); 0: as modelled", PAYLOAD_MASS_RANGE),))
        self.payload_inertia = self.vector(
            "payload_inertia_error", 3, PARAMETER,
            [f"the payload's principal moment about {a} at its centre of mass minus the {i} kg.m2 the controller's "
             "model knows (assumed: axes of {P}); 0: as modelled" for a, i in zip("xyz", _PAPER.platform_inertia)],
            "kg.m2", np.zeros(3), valid=PAYLOAD_INERTIA_RANGE)
        self.payload_com = self.vector(
            "payload_com_error", 3, PARAMETER,
            [f"the payload's centre of mass along {a} of {{P}} from o_P, where the controller's model puts it "
             "(assumed: the platform rigid, the offset fixed in {P}); 0: as modelled" for a in "xyz"],
            "m", np.zeros(3), valid=PAYLOAD_COM_RANGE)
        self.initial_pose = self.vector("initial_pose", 6, PARAMETER,
                                        [f"initial platform {n} in {{B}}" for n in POSE_NAMES], POSE_UNITS,
                                        HOME_POSE, valid=POSE_RANGE)
        self.inputs, self.outputs = np.zeros((5, 6)), np.zeros((4, 6))   # shared with the ODE
        self.inputs[0], self.inputs[1] = STATIC_LEG_FORCES, BASE_POSE   # start: the operating point
        self.vector("leg_force", 6, INPUT, "actuator force along the leg, + extends", "N", values=self.inputs[0])
        self.vector("base_pose", 6, INPUT, [f"base {n} in {{W}}" for n in POSE_NAMES], POSE_UNITS,
                    values=self.inputs[1])
        self.vector("base_rate", 6, INPUT, [f"d/dt base {n}" for n in POSE_NAMES], rate_units(POSE_UNITS),
                    values=self.inputs[2])
        self.vector("base_acc", 6, INPUT, [f"d2/dt2 base {n}" for n in POSE_NAMES], acc_units(POSE_UNITS),
                    values=self.inputs[3])
        self.vector("platform_wrench", 6, INPUT, [f"external {n} on the platform at {{P}}'s origin, in {{B}}"
                                                  for n in ("force x", "force y", "force z", "moment x", "moment y",
                                                            "moment z")], ("N", "N", "N", "N.m", "N.m", "N.m"),
                    values=self.inputs[4])
        self.outputs[0] = StewartParams.paper().home_lengths
        self.vector("leg_length", 6, OUTPUT, "leg length B_i to a_i", "m", values=self.outputs[0])
        self.vector("leg_rate", 6, OUTPUT, "leg extension rate", "m/s", values=self.outputs[1])
        self.vector("pose_rate", 6, OUTPUT, [f"d/dt platform {n}" for n in POSE_NAMES], rate_units(POSE_UNITS),
                    values=self.outputs[2])
        self.vector("leg_force_actual", 6, OUTPUT, "force the actuator delivers to the leg (after lag, limit and "
                    "friction), + extends", "N", values=self.outputs[3])
        self.x = np.r_[HOME_POSE, np.zeros(12)]   # pose, twist, motor forces (used with a bandwidth)
        self.vector("pose", 6, OUTPUT, [f"platform {n} in {{B}}" for n in POSE_NAMES], POSE_UNITS,
                    values=self.x[:6])
        self.ode = None

    def initialize(self):
        check_body(_PAPER.platform_mass + self.payload["payload_mass_error"], _PAPER.platform_inertia
                   + self.payload_inertia, "the payload")
        params = StewartParams.paper(stroke=(-self.stroke, self.stroke),
                                     platform_mass=_PAPER.platform_mass + self.payload["payload_mass_error"],
                                     platform_inertia=_PAPER.platform_inertia + self.payload_inertia,
                                     platform_com=_PAPER.platform_com + self.payload_com)
        a = self.actuator
        actuator = Actuator(a["actuator_bandwidth"], a["reflected_mass"], a["coulomb_friction"], a["viscous_friction"],
                            a["friction_velocity"], a["actuator_force_limit"])
        self.ode = HexapodODE(params, FIDELITIES[self.fidelity], bool(self.moving_base),
                              INTEGRATORS[self.integrator], self.max_step, self.inputs, self.outputs, actuator,
                              self.tolerance)
        self.x[12:] = 0.0   # motor forces of an earlier evaluation in initialization mode: gone, as native
        if self.start_equilibrium:
            self.inputs[0] = holding_forces(params, self.ode.base_mode, self.ode.legs, self.initial_pose,
                                            self.inputs[1:5])
        self.state = self.x[:12 + actuator.states]   # the ODE's state: a view of x
        self.state[:] = self.ode.initial_state(self.initial_pose)
        self.ode.advance(self.state, 0.0)

    def step(self, t, h):
        self.ode.t0 = t
        self.ode.advance(self.state, h)

    def extra_state(self):
        return self.x.copy()

    def set_extra_state(self, extra):
        self.x[:] = extra
