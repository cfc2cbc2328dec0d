"""FMU: telescope pointing as a base-motion source for the hexapod.

Outputs the motion of the hexapod's base {B} in {W} (pose, rates, accelerations), the
axis angles, and the platform's reference pose (home + the elevation-dependent
subreflector correction) with its derivatives, all analytic (plant.telescope.model, whose C
kernel fills a whole block of output rows in one call).

The profile is a known function of time, so it is evaluated ahead in blocks of BLOCK
communication points (one vectorised call costs about what one point does); a step off
the block's grid (another step size, a restored state) starts a new block there.

The antenna's own axis servo (servo_bandwidth > 0): each axis follows the profile, now
the command, through w^2 / (s^2 + 2 zeta w s + w^2); its state is integrated step by step
in the C (mb_tel_servo_advance: RK4 with the command's analytic angles and rates at both
ends of the step, Hermite-interpolated between them), base_*, reference_* and axis* are
the actual motion and command_base_* the commanded one. Off (0, the default), the outputs
are today's block rows, and command_base_* equal base_*.
"""
import pathlib
from dataclasses import replace

import numpy as np

from fmu_src.operating_point import START_AZ_EL
from fmu_src.slave import (
    INPUT,
    OUTPUT,
    PARAMETER,
    POSE_UNITS,
    POSITIVE_RATE,
    POSITIVE_TIME,
    GuardedSlave,
    acc_units,
    rate_units,
)
from plant.hexapod.model import HOME_POSE, S_BAND_POSE
from plant.telescope import model as telescope
from plant.telescope import replay

PROFILES = telescope.PROFILE_KINDS   # slew, sidereal, paper (the base and platform motion of Yao et al.)
BLOCK = 1000
POSE_NAMES = ("x", "y", "z", "roll", "pitch", "yaw")
WRENCH_NAMES = ("force x", "force y", "force z", "moment x", "moment y", "moment z")
WRENCH_UNITS = ("N", "N", "N", "N.m", "N.m", "N.m")
SHAPE_UNITS = ("1", "1", "1", "rad/m", "rad/m", "rad/m")   # m of sway per m of q; rad per m
# Assumed support values (the modes are off by default: support_frequency 0): a 1.8 Hz class
# as AtLAST's first support mode (A&A 694 A142, 2025); 1.5 % structural damping; 10 t of modal
# mass (the kit's 2.1 t subreflector and 2.3 t of hexapod legs, the apex structure and part of
# the quadripod's legs); sway along {B}'s x and y with the tilt a cantilever's tip carries
# under a tip load, 1.5 / L with the 25 m legs (0.06 rad/m).
SUPPORT_SHAPES = ((1.0, 0.0, 0.0, 0.0, 0.06, 0.0), (0.0, 1.0, 0.0, -0.06, 0.0, 0.0))


class Telescope(GuardedSlave):
    description = ("Alt-azimuth telescope pointing (slew, sidereal tracking, paper manoeuvre, a replayed table) -> "
                   "hexapod base motion")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        tianma = telescope.TelescopeParams.tianma()
        self.enumeration("profile", "motion profile", PROFILES, 0)
        turn, quarter, positive = (-2 * np.pi, 2 * np.pi), (0.0, np.pi / 2), (POSITIVE_RATE, None)
        self.settings = self.parameters((
            ("start_azimuth", "rad", START_AZ_EL[0],
             "slew start azimuth, astronomical (north through east; within one turn either way)", turn),
            ("start_elevation", "rad", START_AZ_EL[1], "slew start elevation", quarter),
            ("target_azimuth", "rad", np.radians(90.0),
             "slew target azimuth, astronomical (north through east; within one turn either way)", turn),
            ("target_elevation", "rad", np.radians(60.0), "slew target elevation", quarter),
            ("az_rate_max", "rad/s", tianma.az_rate_max, "azimuth rate limit (assumed); > 0", positive),
            ("az_acc_max", "rad/s2", tianma.az_acc_max, "azimuth acceleration limit (assumed); > 0", positive),
            ("el_rate_max", "rad/s", tianma.el_rate_max, "elevation rate limit (assumed); > 0", positive),
            ("el_acc_max", "rad/s2", tianma.el_acc_max, "elevation acceleration limit (assumed); > 0", positive),
            ("lever_arm", "m", tianma.lever_arm, "axis intersection to base along boresight (assumed)", (0.0, None)),
            ("latitude", "rad", tianma.latitude, "site latitude", (-np.pi / 2, np.pi / 2)),
            ("longitude", "rad", tianma.longitude, "site longitude (east +)", (-np.pi, np.pi)),
            ("right_ascension", "rad", 0.0, "tracked source right ascension (apparent, of date)", (0.0, 2 * np.pi)),
            ("declination", "rad", tianma.latitude + np.radians(0.2), "tracked source declination",
             (-np.pi / 2, np.pi / 2)),
            ("utc_start", "s", 1.7e9, "UTC at t = 0, seconds since 1970-01-01", (0.0, None)),
            ("paper_duration", "s", 6.0, "duration of the paper's stress manoeuvre; > 0", (POSITIVE_TIME, None)),
            ("start_delay", "s", 0.0, "the profile starts this late; before it, the start pointing holds",
             (0.0, None)),
            ("servo_bandwidth", "1/s", 0.0,
             "the antenna's axis servo bandwidth in Hz (natural frequency of each axis's "
             "second-order loop); 0 = off, the axes follow the command exactly. Assumed: large-antenna axis servos "
             "have ~0.5-1 Hz locked-rotor bandwidth (SRT, GBT)", (0.0, 10.0)),
            ("servo_damping", "1", 0.7, "damping ratio of the antenna's axis servo (assumed)", (0.01, 10.0)),
            ("replay_smoothing", "s", replay.SMOOTHING_TIME, "profile replay: the table's smoothing time h "
             "(docs/conventions/telescope.md gives the error it costs); > 0", (POSITIVE_TIME, 60.0)),
        ))
        pose_desc = lambda prefix: [f"{prefix} {n}" for n in POSE_NAMES]
        self.now = np.zeros(66)   # every output: one row of the evaluated block (60), the support's sway
        self.now[18:24] = tianma.home
        for start, (name, size, desc, units) in zip((0, 6, 12, 18, 24, 30, 36, 38, 40, 46, 52, 58), (
            ("base_pose", 6, pose_desc("base, in {W},"), POSE_UNITS),
            ("base_rate", 6, pose_desc("d/dt base"), rate_units(POSE_UNITS)),
            ("base_acc", 6, pose_desc("d2/dt2 base"), acc_units(POSE_UNITS)),
            ("reference_pose", 6, pose_desc("platform reference, in {B},"), POSE_UNITS),
            ("reference_rate", 6, pose_desc("d/dt reference"), rate_units(POSE_UNITS)),
            ("reference_acc", 6, pose_desc("d2/dt2 reference"), acc_units(POSE_UNITS)),
            ("axis", 2, ["astronomical azimuth (north through east; the mount angle A = 180 deg - it)", "elevation"],
             "rad"),
            ("axis_rate", 2, ["astronomical azimuth rate", "elevation rate"], "rad/s"),
            ("command_base_pose", 6, pose_desc("commanded base, in {W},"), POSE_UNITS),
            ("command_base_rate", 6, pose_desc("d/dt commanded base"), rate_units(POSE_UNITS)),
            ("command_base_acc", 6, pose_desc("d2/dt2 commanded base"), acc_units(POSE_UNITS)),
            ("axis_acc", 2, ["astronomical azimuth acceleration", "elevation acceleration"], "rad/s2"),
        )):
            self.vector(name, size, OUTPUT, desc, units, values=self.now[start:start + size])
        self._support_variables(tianma)
        self.text = self.strings((   # last (slave.strings)
            ("replay_table", "", "profile replay: the table of az/el samples it follows, a prepared replay table "
             "(python -m fmu_src.replay_table LOG; the native FMUs read only these) or, the pythonfmu FMU, a CSV or "
             "npz file (plant/telescope/replay.py: columns and units, checks, smoothing); an absolute path, "
             "relative to the working directory (a scenario file's parameter: to its folder), or resource:<name> "
             "in the FMU's resources folder (an SSP export puts it there)"),))

    def _support_variables(self, tianma):
        """The flexible feed support's parameters, its load input and its sway output."""
        per_mode = lambda what: [f"mode {j + 1}: {what}" for j in range(telescope.SUPPORT_MODES)]
        self.support_settings = {name: self.vector(name, 2, PARAMETER, per_mode(desc), unit, start=start, valid=valid)
                                 for name, unit, start, desc, valid in (
            ("support_frequency", "1/s", (0.0, 0.0), "natural frequency in Hz of the feed support's sway mode; "
             "0 = off, a rigid support. Assumed 1.5-2.5 Hz: AtLAST's first support mode is 1.8 Hz "
             "(A&A 694 A142, 2025)", (0.0, 50.0)),
            ("support_damping", "1", (0.015, 0.015), "damping ratio of the sway mode (assumed 1.5 %, structural)",
             (0.0, 0.99)),
            ("support_modal_mass", "kg", (1e4, 1e4), "modal mass of the sway mode (assumed 10 t: subreflector, "
             "hexapod, apex and part of the quadripod's legs)", (1e-9, None)),
            ("support_participation", "1", (1.0, 1.0), "participation: the mode's forcing is -participation x the "
             "rigid base's acceleration along the shape (assumed 1: the apex's mass dominates)", (-10.0, 10.0)),
        )}
        for j, shape in enumerate(SUPPORT_SHAPES):
            name = f"support_shape_{j + 1}"
            self.support_settings[name] = self.vector(
                name, 6, PARAMETER, [f"mode {j + 1}: base {n} per unit modal coordinate, in {{B}} (assumed: sway "
                                     "with a cantilever tip's tilt 1.5 / 25 m)" for n in POSE_NAMES],
                SHAPE_UNITS, start=shape, valid=(-1e3, 1e3))
        self.support_gain = self.parameters((
            ("support_load_gain", "1", 1.0, "the modes' force from support_load times this: 1 = the wrench alone; "
             "> 1 adds the quadripod legs' own drag as a share of it (assumed: the same gusts, fully coherent)",
             (0.0, 10.0)),))
        self.support_settings["support_load_point"] = self.vector(
            "support_load_point", 3, PARAMETER, [f"point where support_load's moment is taken, {n} in {{B}} (the "
                                                 "platform's home origin: where Wind gives its wrench)" for n in "xyz"],
            "m", start=tianma.home[:3], valid=(-100.0, 100.0))
        self.support_settings["support_preload"] = self.vector(
            "support_preload", 6, PARAMETER, [f"steady {n} on the support the modes start in equilibrium under, in "
                                              "{B} (e.g. the mean wind's drag)" for n in WRENCH_NAMES],
            WRENCH_UNITS, start=np.zeros(6), valid=(-1e7, 1e7))
        self.support_load = self.vector("support_load", 6, INPUT, [f"{n} on the feed support's tip (through the "
                                                                   "hexapod), in {B}" for n in WRENCH_NAMES],
                                        WRENCH_UNITS, start=np.zeros(6))
        self.vector("support_sway", 6, OUTPUT, [f"the support's sway of the base: {n} in {{B}}" for n in POSE_NAMES],
                    POSE_UNITS, values=self.now[60:66])

    def initialize(self):
        s = self.settings
        kind = PROFILES[self.profile]
        self.params = replace(telescope.TelescopeParams.tianma(), lever_arm=s["lever_arm"],
                              latitude=s["latitude"], longitude=s["longitude"],
                              az_rate_max=s["az_rate_max"], az_acc_max=s["az_acc_max"],
                              el_rate_max=s["el_rate_max"], el_acc_max=s["el_acc_max"])
        table = replay.load(self._table_path(), self.params, smoothing_time=s["replay_smoothing"]) \
            if kind == "replay" else None
        self.motion = telescope.motion_profile(
            kind, (s["start_azimuth"], s["start_elevation"]), (s["target_azimuth"], s["target_elevation"]),
            ra=s["right_ascension"], dec=s["declination"], utc_start=s["utc_start"],
            paper_duration=s["paper_duration"], start_delay=s["start_delay"],
            reference=(HOME_POSE, S_BAND_POSE), replay=table)   # the paper's platform motion: home to S-band
        self.block_t, self.block_h, self.block = np.inf, 0.0, None
        g = {name: np.array(values) for name, values in self.support_settings.items()}
        self.modes = telescope.support(g["support_frequency"], g["support_damping"], g["support_modal_mass"],
                                       g["support_participation"], [g["support_shape_1"], g["support_shape_2"]],
                                       self.support_gain["support_load_gain"], g["support_load_point"],
                                       g["support_preload"])
        self.support = telescope.support_on(self.modes)
        self.support_state = np.zeros(6)
        self._row = telescope.ffi.from_buffer("double[]", self.now)
        self._pointers = [telescope.ffi.from_buffer("double[]", a) for a in (self.support_load, self.support_state)]
        self.servo = s["servo_bandwidth"] > 0
        if self.servo:
            telescope.check_servo(s["servo_bandwidth"], s["servo_damping"])
            self.command = telescope.profile_axes(self.params, self.motion, 0.0)[0]
            self.state = self.command[[0, 1, 3, 4]].copy()   # starts on the command
            self._publish_servo(0.0)
        else:
            self._publish(0.0, 0.0)
        self._sway(None)

    def _table_path(self):
        """replay_table as a path: "resource:<name>" is a file in this FMU's resources folder
        (where scenarios/ssp.py puts the table an SSP carries), anything else a path."""
        name = self.text["replay_table"]
        if name.startswith(replay.RESOURCE):
            return str(pathlib.Path(self.resources or ".") / name[len(replay.RESOURCE):])
        return name

    def step(self, t, h):
        if self.servo:
            command = telescope.profile_axes(self.params, self.motion, t + h)[0]
            telescope.servo_advance(self.settings["servo_bandwidth"], self.settings["servo_damping"], h,
                                    self.command, command, self.state)
            self.command = command
            self._publish_servo(t + h)
        else:
            self._publish(t + h, h)
        self._sway(h)

    def _sway(self, h):
        """The support's modes over the step h (None: the start) added to the rigid row."""
        if self.support:
            telescope.support_advance(self.modes, h, *self._pointers, self._row, self._row + 60)

    def _publish_servo(self, t):
        s = self.settings
        self.now[:60] = telescope.servo_row(self.params, self.motion, s["servo_bandwidth"], s["servo_damping"], t,
                                            self.command, self.state)

    def extra_state(self):
        return ((self.command.copy(), self.state.copy()) if self.servo else None, self.support_state.copy())

    def set_extra_state(self, extra):
        servo, support = extra
        if servo is not None:
            self.command, self.state = (a.copy() for a in servo)
        self.support_state[:] = support   # in place: the C holds a pointer to it

    def _publish(self, t, h):
        index = round((t - self.block_t) / self.block_h) if self.block_h == h and h > 0 else -1
        if not (0 <= index < BLOCK and abs(self.block_t + index * h - t) <= 1e-9 * max(1.0, abs(t))):
            self.block_t, self.block_h, index = t, h, 0
            self.block = telescope.fmu_outputs(self.params, self.motion, t + h * np.arange(BLOCK if h > 0 else 1))
        self.now[:60] = self.block[index]

    def _evaluate(self, times):
        """Today's 40 outputs (no servo) at the given times, (n, 40) in the order of self.now."""
        return telescope.telescope_outputs(self.params, self.motion, times)
