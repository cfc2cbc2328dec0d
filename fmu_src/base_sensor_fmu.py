"""FMU: what the controller's feedforward knows of the base motion.

Between Telescope (the actual motion: axis, axis_rate, base_* into axis, axis_rate,
true_base_*; FMI names are unique, so the true inputs carry the prefix) and the
controller's base_pose/rate/acc inputs (from base_pose, base_rate, base_acc here):
source 0, the antenna's axis encoders (quantised angles, differenced and filtered, through
the telescope kernel's base-motion formula); source 1, an inertial sensor on the base
(gyro and accelerometer with white noise and bias; pose from the encoders). The numbers
come from the C kernel plant/c/base_estimate.c (law in base_estimate.h), the same the native
FMU compiles. Default values are assumed, from comparable instruments (README).
"""
import numpy as np

from fmu_src.operating_point import AXIS, BASE_POSE
from fmu_src.slave import INPUT, OUTPUT, PARAMETER, POSE_UNITS, GuardedSlave, acc_units, rate_units
from plant._kernel import ffi, lib
from plant.errors import InvalidInputError
from plant.telescope import model as telescope

SOURCES = ("encoders", "imu")   # enum mb_bs_source
POSE_NAMES = ("x", "y", "z", "roll", "pitch", "yaw")
ARCSEC = np.pi / 648000
INPUTS = (("axis", 0, 2), ("axis_rate", 2, 2), ("true_base_pose", 4, 6), ("true_base_rate", 10, 6),
          ("true_base_acc", 16, 6))   # (name, start in self.truth, size), in value-reference order


class BaseSensor(GuardedSlave):
    description = "Base-motion estimate for the feedforward: axis encoders or an IMU on the base"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.enumeration("source", "what measures the base", SOURCES, 0)
        self.integer("seed", "seed of the sensor noise (plant/c/random.h)", 1, (0, 2 ** 31 - 1))
        self.settings = self.parameters((
            ("encoder_resolution", "rad", 0.1 * ARCSEC, "axis encoder quantum; 0 = exact angles. Assumed: "
             "0.1 arcsec class, as on the GBT / Effelsberg / SRT axis encoders", (0.0, 1e-2)),
            ("rate_cutoff", "1/s", 5.0, "cut-off in Hz of the first-order low-pass on each backward difference "
             "(rates, accelerations); 0 = plain difference (assumed)", (0.0, 1e4)),
            ("gyro_noise_density", "rad/s/sqrt(Hz)", np.radians(0.01) / 60, "gyro white noise density (angle "
             "random walk). Assumed: 0.01 deg/sqrt(h), a fibre-optic gyro", (0.0, 1.0)),
            ("gyro_bias", "rad/s", np.radians(0.05) / 3600, "gyro constant bias on each axis. Assumed: "
             "0.05 deg/h, a fibre-optic gyro", (-1.0, 1.0)),
            ("accel_noise_density", "m/s2/sqrt(Hz)", 50e-6 * 9.80665, "accelerometer white noise density. "
             "Assumed: 50 ug/sqrt(Hz), a navigation-grade servo accelerometer", (0.0, 1.0)),
            ("accel_bias", "m/s2", 100e-6 * 9.80665, "accelerometer constant bias on each axis (after gravity "
             "compensation). Assumed: 100 ug", (-1.0, 1.0)),
            ("lever_arm", "m", telescope.TelescopeParams.tianma().lever_arm,
             "axis intersection to base along boresight (as Telescope's; assumed)", (0.0, None)),
        ))
        self.alignment = self.vector("imu_alignment", 3, PARAMETER, [
            f"IMU misalignment: {n} of its axes in the base's (rotation as the pose's angles); the IMU reads R v "
            "for the base's rate and acceleration v, gravity compensated in its own axes (assumed); 0: aligned"
            for n in ("roll", "pitch", "yaw")], "rad", np.zeros(3), valid=(-0.01, 0.01))
        self.truth = np.zeros(22)      # the inputs, INPUTS
        self.truth[0:2], self.truth[4:10] = AXIS, BASE_POSE   # start: the operating point, at rest
        units_of = {"axis": "rad", "axis_rate": "rad/s", "true_base_pose": POSE_UNITS,
                    "true_base_rate": rate_units(POSE_UNITS), "true_base_acc": acc_units(POSE_UNITS)}
        for name, start, size in INPUTS:
            units = units_of[name]
            axes = [f"actual astronomical azimuth{name[4:]}", f"actual elevation{name[4:]}"]   # "", "_rate"
            desc = [a.replace("_", " ") + " (Telescope)" for a in axes] if size == 2 else \
                [f"actual {name[5:].replace('_', ' ')} {n} (Telescope)" for n in POSE_NAMES]
            self.vector(name, size, INPUT, desc, units, values=self.truth[start:start + size])
        self.now = np.zeros(18)
        pose_desc = lambda prefix: [f"{prefix} {n}" for n in POSE_NAMES]
        for start, (name, desc, units) in zip((0, 6, 12), (
                ("base_pose", pose_desc("estimated base, in {W},"), POSE_UNITS),
                ("base_rate", pose_desc("estimated d/dt base"), rate_units(POSE_UNITS)),
                ("base_acc", pose_desc("estimated d2/dt2 base"), acc_units(POSE_UNITS)))):
            self.vector(name, 6, OUTPUT, desc, units, values=self.now[start:start + 6])

    def initialize(self):
        s = self.settings
        self.params = ffi.new("mb_bs_params *")
        self.params.source = self.source
        for name, value in s.items():
            setattr(self.params, name, float(value))
        self.params.imu_alignment = [float(a) for a in self.alignment]
        if lib.mb_bs_check(self.params):
            raise InvalidInputError("BaseSensor parameters must be finite, the densities, resolution, cut-off "
                                    "and lever arm >= 0, source 0 or 1")
        self.state = ffi.new("mb_bs_state *")
        lib.mb_bs_start(self.params, self.seed, *self._in(0, 2, 4, 10, 16), self.state, self._out())

    def _in(self, *starts):
        return [ffi.from_buffer("double[]", self.truth[k:]) for k in starts]

    def _out(self):
        return ffi.from_buffer("double[]", self.now)

    def step(self, t, h):
        bad = [name for name, start, size in INPUTS if not np.all(np.isfinite(self.truth[start:start + size]))]
        if bad:
            raise InvalidInputError(f"inputs must be finite: {', '.join(bad)}")
        lib.mb_bs_step(self.params, h, *self._in(0, 4, 10, 16), self.state, self._out())

    def extra_state(self):
        return bytes(ffi.buffer(self.state))

    def set_extra_state(self, extra):
        ffi.buffer(self.state)[:] = extra
