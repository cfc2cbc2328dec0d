"""The telescope that moves the hexapod's base: axis profiles -> base and reference motion.

Law: docs/conventions/telescope.md; frames and poses: docs/conventions/stewart-6ups.md. SI inside
(m, rad, s); angles are radians in every argument. All functions are vectorised over a
1-D array of times and every derivative is analytic (chain rule), so a consumer never
differences samples.

The numbers come from plant/c/telescope.c (the native FMUs compile the same file); this
module holds the Python API and its validation, and turns the C's status codes into
InvalidInputError with a message naming the problem.

Pipeline: a profile (``slew``, ``sidereal_track``, ``paper_manoeuvre``, ``replay_track``
of a table read and smoothed by plant/telescope/replay.py) gives the axis
angles A (the mount's azimuth angle), E (elevation) and their first two derivatives as an
``AxisMotion``;
``base_motion`` / ``base_twist`` turn it into the motion of the hexapod's base {B} in
{W}; ``reference_pose`` into the subreflector pose the hexapod must follow in {B}.

Modelling assumptions (beyond the values labelled "assumed" in ``TelescopeParams``):

* {W} is treated as inertial: the Earth's rotation (7.3e-5 rad/s) is left out of the
  base's angular velocity; its centripetal and Coriolis terms on the hexapod are of
  order 1e-8 m/s^2.
* R_WB = Rz(A) Rx(90 deg - E) as the spec writes it, {W} = (east, north, up): A is the
  mount's angle, A = 180 deg - Az with Az the astronomical azimuth (north through east).
  The conversion happens at the edge, in the C: slew targets are astronomical azimuths,
  a sidereal track's azimuth is computed astronomically and turned into A, and the
  telescope FMU's ``axis`` output is Az again (``AxisMotion.azimuth`` here). The
  paper's manoeuvre is given as base yaw = A directly.
"""
import math
import weakref
from dataclasses import dataclass
from datetime import datetime, timezone
from functools import lru_cache

import numpy as np

from plant._kernel import ffi, lib
from plant.errors import InvalidInputError
from plant.integrators import substep_count

EARTH_RATE = lib.mb_tel_earth_rate()   # rad/s, the rate at which the hour angle advances
_UNIX_EPOCH = datetime(1970, 1, 1, tzinfo=timezone.utc)
_E_TOLERANCE = 1e-9                 # rad of rounding allowed outside [0, 90 deg] (as in the C)
PROFILE_KINDS = ("slew", "sidereal", "paper", "replay")   # enum mb_tel_kind


def _finite(name, value):
    """value as a float array, or InvalidInputError naming ``name`` if any is NaN/inf."""
    array = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(array)):
        raise InvalidInputError(f"{name} must be finite, got {value!r}")
    return array


def _check_elevation(name, E):
    if np.any(E < -_E_TOLERANCE) or np.any(E > np.pi / 2 + _E_TOLERANCE):
        raise InvalidInputError(f"{name} must lie in [0, 90] deg, got "
                                f"{np.degrees(np.min(E)):.6g}..{np.degrees(np.max(E)):.6g} deg")


def _times(t):
    """t as a 1-D float array, finite and strictly increasing."""
    t = np.atleast_1d(_finite("t", t))
    if t.ndim != 1:
        raise InvalidInputError(f"t must be a scalar or a 1-D array, got shape {t.shape}")
    if np.any(np.diff(t) <= 0):
        raise InvalidInputError("t must be strictly increasing")
    return t


@dataclass(frozen=True)
class TelescopeParams:
    """Site, lever arm, axis limits and subreflector correction of the antenna (SI)."""

    latitude: float          # rad, geodetic, north positive
    longitude: float         # rad, east positive
    lever_arm: float         # m, axis intersection -> base along the boresight
    az_rate_max: float       # rad/s
    az_acc_max: float        # rad/s^2
    el_rate_max: float       # rad/s
    el_acc_max: float        # rad/s^2
    b_y: float               # m, Δy(E) = a_y + b_y sin E + c_y cos E
    c_y: float               # m
    b_z: float               # m, Δz(E) = a_z + b_z sin E + c_z cos E
    c_z: float               # m
    home: tuple              # platform pose in {B} at E = 90 deg [m, m, m, rad, rad, rad]

    def __post_init__(self):
        for name in ("latitude", "longitude", "lever_arm", "b_y", "c_y", "b_z", "c_z"):
            _finite(name, getattr(self, name))
        if abs(self.latitude) > np.pi / 2:
            raise InvalidInputError(f"latitude must lie in [-90, 90] deg, got {self.latitude!r}")
        if self.lever_arm < 0:
            raise InvalidInputError(f"lever_arm must be >= 0, got {self.lever_arm!r}")
        for name in ("az_rate_max", "az_acc_max", "el_rate_max", "el_acc_max"):
            if not _finite(name, getattr(self, name)) > 0:
                raise InvalidInputError(f"{name} must be > 0, got {getattr(self, name)!r}")
        home = _finite("home", self.home)
        if home.shape != (6,):
            raise InvalidInputError(f"home must hold 6 numbers, got shape {home.shape}")
        object.__setattr__(self, "home", tuple(home.tolist()))

    @classmethod
    def tianma(cls):
        """Shanghai Tianma 65 m. Site from public sources; the rest is assumed (spec):
        L = 25 m; axis limits like Effelsberg/GBT (az 0.5 deg/s, 0.25 deg/s^2; el 0.3
        deg/s, 0.25 deg/s^2); gravity correction c_y = 20 mm, b_z = -15 mm (b_y = c_z = 0).
        For the paper's moving-base case use ``dataclasses.replace(p, lever_arm=0.0)``."""
        return cls(latitude=np.radians(31.09), longitude=np.radians(121.14), lever_arm=25.0,
                   az_rate_max=np.radians(0.5), az_acc_max=np.radians(0.25),
                   el_rate_max=np.radians(0.3), el_acc_max=np.radians(0.25),
                   b_y=0.0, c_y=0.020, b_z=-0.015, c_z=0.0,
                   home=(0.0, 0.0, -2.6815, 0.0, 0.0, 0.0))

    @property
    def a_y(self):
        """Chosen so that Δy(90 deg) = 0: the home pose holds at the zenith."""
        return -self.b_y

    @property
    def a_z(self):
        """Chosen so that Δz(90 deg) = 0."""
        return -self.b_z


@dataclass(frozen=True, eq=False)
class AxisMotion:
    """Mount azimuth angle A (= 180 deg - Az, astronomical) and elevation E (rad) with first
    and second time derivatives at times t."""

    t: np.ndarray
    A: np.ndarray
    A_dot: np.ndarray
    A_ddot: np.ndarray
    E: np.ndarray
    E_dot: np.ndarray
    E_ddot: np.ndarray

    @property
    def azimuth(self):
        """Astronomical azimuth Az = 180 deg - A (north through east) [rad]."""
        return np.pi - self.A

    def __post_init__(self):
        t = _times(self.t)
        for name in ("A", "A_dot", "A_ddot", "E", "E_dot", "E_ddot"):
            value = _finite(name, getattr(self, name))
            if value.shape != t.shape:
                raise InvalidInputError(f"{name} has shape {value.shape}, t has {t.shape}")
            object.__setattr__(self, name, value)
        object.__setattr__(self, "t", t)
        _check_elevation("elevation E", self.E)


# --- the C kernel ------------------------------------------------------------------

def _doubles(array):
    """A double* onto array (a contiguous float64 copy if it is not one; outputs are)."""
    return ffi.from_buffer("double[]", np.ascontiguousarray(array, dtype=float))


@lru_cache(maxsize=64)
def _c_params(params):
    """params as an mb_tel_params (cached: TelescopeParams is frozen)."""
    c = ffi.new("mb_tel_params *")
    for name in ("latitude", "longitude", "lever_arm", "az_rate_max", "az_acc_max", "el_rate_max",
                 "el_acc_max", "b_y", "c_y", "b_z", "c_z"):
        setattr(c, name, float(getattr(params, name)))
    c.home = list(params.home)
    return c


# profile -> the arrays its replay_* pointers point into
_REPLAY_ARRAYS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def motion_profile(kind, start_az_el=(0.0, 0.0), target_az_el=(0.0, 0.0), ra=0.0, dec=0.0,
                   utc_start=0.0, paper_duration=6.0, start_delay=0.0,
                   reference=((0.0,) * 6, (0.0,) * 6), replay=None):
    """A profile for the C (an mb_tel_profile): ``kind`` one of PROFILE_KINDS, angles in
    rad, ``utc_start`` in Unix seconds, ``reference`` the (start, stop) poses of the
    paper's platform quintic, ``replay`` the replay profile's spline (a
    plant.telescope.replay.Replay; its arrays live as long as the profile). Checked where
    it is used (InvalidInputError)."""
    if kind not in PROFILE_KINDS:
        raise InvalidInputError(f"profile must be one of {PROFILE_KINDS}, got {kind!r}")
    c = ffi.new("mb_tel_profile *")
    if kind == "replay":
        if replay is None:
            raise InvalidInputError("the replay profile needs a table (replay=)")
        arrays = (np.ascontiguousarray(replay.breakpoints, dtype=float),
                  np.ascontiguousarray(replay.coefficients, dtype=float))
        bad = ffi.new("int *")
        if arrays[1].shape != (arrays[0].size - 1, 8) or lib.mb_tel_replay_check(arrays[0].size, _doubles(arrays[0]),
                                                                                  _doubles(arrays[1]), bad):
            raise InvalidInputError(f"replay spline of {replay.source}: "
                                    + ffi.string(lib.mb_tel_status_text(lib.MB_TEL_REPLAY_TABLE)).decode()
                                    + (f" (breakpoint {bad[0]})" if bad[0] >= 0 else ""))
        c.replay_n, c.replay_t, c.replay_coef = arrays[0].size, _doubles(arrays[0]), _doubles(arrays[1])
        _REPLAY_ARRAYS[c] = arrays
    c.kind = PROFILE_KINDS.index(kind)
    (c.start_az, c.start_el), (c.target_az, c.target_el) = start_az_el, target_az_el
    c.ra, c.dec, c.utc_start = ra, dec, utc_start
    c.paper_duration, c.start_delay = paper_duration, start_delay
    c.ref_start, c.ref_stop = (list(np.asarray(pose, dtype=float)) for pose in reference)
    return c


# the settings each kind uses: mb_tel_profile field -> name in messages (the FMU's parameter)
_PROFILE_FIELDS = {"slew": {"start_az": "start_azimuth", "start_el": "start_elevation",
                            "target_az": "target_azimuth", "target_el": "target_elevation"},
                   "sidereal": {"ra": "right_ascension", "dec": "declination", "utc_start": "utc_start"},
                   "paper": {"paper_duration": "paper_duration"}}


def _status_error(status, profile, t, first_bad):
    """InvalidInputError for a non-zero mb_tel status of ``profile`` at times t."""
    kind = PROFILE_KINDS[profile.kind] if 0 <= profile.kind < len(PROFILE_KINDS) else None
    if status == lib.MB_TEL_ELEVATION_RANGE:
        E = np.array([profile.start_el, profile.target_el])
        return InvalidInputError(f"slew elevation must lie in [0, 90] deg, got "
                                 f"{np.degrees(np.min(E)):.6g}..{np.degrees(np.max(E)):.6g} deg")
    if status == lib.MB_TEL_DEC_RANGE:
        return InvalidInputError(f"dec must lie in [-90, 90] deg, got {np.degrees(profile.dec):.6g} deg")
    if status == lib.MB_TEL_ZENITH:
        return InvalidInputError("the source passes through the zenith, where the azimuth is "
                                 "undefined; offset dec from the latitude (near_zenith_source)")
    if status == lib.MB_TEL_BELOW_HORIZON:
        return InvalidInputError("the source is below the horizon at t = "
                                 f"{t[first_bad] - profile.start_delay} s")
    if status == lib.MB_TEL_DURATION_NOT_POSITIVE:
        return InvalidInputError(f"T must be > 0, got {profile.paper_duration!r}")
    if status == lib.MB_TEL_NONFINITE:
        if first_bad >= 0:
            return InvalidInputError(f"t must be finite, got {t[first_bad]!r} at index {first_bad}")
        for field, name in {"start_delay": "start_delay", **_PROFILE_FIELDS.get(kind, {})}.items():
            if not np.isfinite(getattr(profile, field)):
                return InvalidInputError(f"{name} must be finite, got {getattr(profile, field)!r}")
    return InvalidInputError(ffi.string(lib.mb_tel_status_text(status)).decode())


def _axes(params, profile, t):
    """(n, 6) axes [A, A', A'', E, E', E''] of ``profile`` at the float array t."""
    axes, bad = np.empty((t.size, 6)), ffi.new("int *")
    status = lib.mb_tel_axes(_c_params(params), profile, t.size, _doubles(t), _doubles(axes), bad)
    if status:
        raise _status_error(status, profile, t, bad[0])
    return AxisMotion(t, *axes.T.copy())


def _axis_rows(axes):
    return np.ascontiguousarray(np.column_stack([axes.A, axes.A_dot, axes.A_ddot,
                                                 axes.E, axes.E_dot, axes.E_ddot]))


def telescope_outputs(params, profile, t):
    """Every output of the telescope source at times t (n,), one C call: (n, 40) rows of
    base pose, rate, acceleration, reference pose, rate, acceleration (6 each), A, E, A', E'.
    The profile (``motion_profile``) is evaluated at t - start_delay; the paper profile's
    reference is its quintic between the two ``reference`` poses."""
    t = np.ascontiguousarray(t, dtype=float)
    rows, bad = np.empty((t.size, 40)), ffi.new("int *")
    status = lib.mb_tel_fmu_rows(_c_params(params), profile, t.size, _doubles(t), _doubles(rows), bad)
    if status:
        raise _status_error(status, profile, t, bad[0])
    return rows


# --- slew -------------------------------------------------------------------------

def _slew_settings(start_az_el, target_az_el):
    (A0, E0), (A1, E1) = _finite("start_az_el", start_az_el), _finite("target_az_el", target_az_el)
    return (float(A0), float(E0)), (float(A1), float(E1))


def slew_duration(params, start_az_el, target_az_el):
    """Seconds until both axes of ``slew`` have arrived (the slower axis decides)."""
    start, target = _slew_settings(start_az_el, target_az_el)
    duration = ffi.new("double *")
    status = lib.mb_tel_slew_duration(_c_params(params), *start, *target, duration)
    if status:
        raise _status_error(status, motion_profile("slew", start, target), np.zeros(0), -1)
    return duration[0]


def slew(params, start_az_el, target_az_el, t):
    """Slew from (Az, E) to (Az, E) [rad], Az the astronomical azimuth (north through east;
    the motion's A = 180 deg - Az), both axes starting at t = 0 with trapezoidal
    profiles at their own limits (rate- and acceleration-limited, triangular when the
    rate limit is never reached); holds the start before 0 and the target once arrived.
    The azimuth moves by target - start literally (no shortest way): the cable wrap
    is the caller's choice."""
    t = _times(t)
    return _axes(params, motion_profile("slew", *_slew_settings(start_az_el, target_az_el)), t)


# --- sidereal tracking ------------------------------------------------------------

def _unix_seconds(utc):
    if not isinstance(utc, datetime):
        raise InvalidInputError(f"utc must be a datetime, got {utc!r}")
    if utc.tzinfo is None:
        utc = utc.replace(tzinfo=timezone.utc)
    return (utc - _UNIX_EPOCH).total_seconds()


def local_sidereal_time(params, utc):
    """Local mean sidereal time (rad, in [0, 2 pi)) at a UTC ``datetime`` (naive = UTC).

    GMST of IAU 1982 (Meeus eq. 12.4) with UTC in place of UT1. Against the apparent
    sidereal time astropy uses this is off by the equation of the equinoxes (<= 1.2 s)
    plus |UT1 - UTC| (<= 0.9 s): <= 0.009 deg of hour angle at worst; the tests measure
    <= 0.0013 deg on the sky against astropy's AltAz in 2024. The C takes Unix seconds
    (the FMU's utc_start): a sub-second UTC is rounded to a double there (0.24 µs in
    2024, 2e-11 rad of LST)."""
    return np.float64(lib.mb_tel_lst(float(params.longitude), _unix_seconds(utc)))


def sidereal_track(params, ra, dec, utc_start, t):
    """Track a source at apparent (of date) right ascension ``ra`` and declination
    ``dec`` [rad] from ``utc_start`` (a ``datetime``, naive = UTC) at times t [s].

    Catalogue (J2000) coordinates must be precessed first: ~0.35 deg by 2025.
    The astronomical azimuth (``.azimuth``, north through east; the motion's A is
    180 deg - Az) is continuous (no 2 pi jumps: atan2's jumps at the culminations are
    unwrapped) and in [0, 2 pi) at t = 0, so step-by-step callers with the same
    utc_start see one continuous curve. Refraction is ignored."""
    t = _times(t)
    ra, dec = float(_finite("ra", ra)), float(_finite("dec", dec))
    return _axes(params, motion_profile("sidereal", ra=ra, dec=dec,
                                        utc_start=_unix_seconds(utc_start)), t)


def near_zenith_source(params, utc_transit, miss=np.radians(0.2)):
    """(ra, dec) of a source that transits at ``utc_transit`` ``miss`` rad south of the
    zenith: the keyhole, where the azimuth rate peaks at EARTH_RATE cos(dec) / sin(miss)
    (it grows as 1/cos E). The default 0.2 deg gives 1.03 deg/s, twice the assumed
    0.5 deg/s azimuth limit."""
    return local_sidereal_time(params, utc_transit), params.latitude - miss


# --- the paper's stress case ----------------------------------------------------------

def paper_manoeuvre(t, T=6.0):
    """The paper's moving-base case: roll = 90 deg - E from 0 to 45 deg and yaw = A from
    0 to 30 deg over T s with s = 10 tau^3 - 15 tau^4 + 6 tau^5; at rest outside [0, T].
    Far past the axis limits (elevation 7.5 deg/s mean, 14.1 deg/s peak): a stress case.
    The paper puts the base at the rotation centre: pair it with
    ``dataclasses.replace(TelescopeParams.tianma(), lever_arm=0.0)``."""
    t = _times(t)
    if not _finite("T", T) > 0:
        raise InvalidInputError(f"T must be > 0, got {T!r}")
    return _axes(_any_params(), motion_profile("paper", paper_duration=float(T)), t)


@lru_cache(maxsize=1)
def _any_params():
    """The C wants parameters with every profile; the paper's axes use none of them."""
    return TelescopeParams.tianma()


# --- a replayed table --------------------------------------------------------------------

def replay_track(params, replay, t, start_delay=0.0):
    """The axes of a replayed table (a plant.telescope.replay.Replay: the table's smoothing
    spline, its first time at t = 0) at times t [s]; the end pointings hold outside it."""
    t = _times(t)
    return _axes(params, motion_profile("replay", replay=replay, start_delay=float(start_delay)), t)


# --- what the axes do to the base and to the reference ---------------------------------

def base_motion(params, axes):
    """Pose of {B} in {W} and its plain time derivatives, each (n, 6): roll = 90 deg - E,
    pitch = 0, yaw = A, p_B = R_WB (0, 0, L) = L (cos E sin A, -cos E cos A, sin E)."""
    pose, rate, acc = (np.empty((axes.A.size, 6)) for _ in range(3))
    lib.mb_tel_base_motion(_c_params(params), axes.A.size, _doubles(_axis_rows(axes)),
                           _doubles(pose), _doubles(rate), _doubles(acc))
    return pose, rate, acc


def base_twist(params, axes):
    """(v_B, w_B, a_B, eps_B), each (n, 3) in {B}: velocity and inertial acceleration of
    the base origin, angular velocity and angular acceleration of {B}.

    w_W = A_dot z_W - E_dot Rz(A) x_W; in {B} (R_WB = Rz(A) Rx(r), r = 90 deg - E) that is
    w_B = (-E_dot, A_dot cos E, A_dot sin E), and eps_B = d(w_B)/dt since w_B x w_B = 0.
    The origin sits at l = (0, 0, L) in {B} on the rotating body: v_B = w_B x l,
    a_B = eps_B x l + w_B x (w_B x l)."""
    v, w, a, eps = (np.empty((axes.A.size, 3)) for _ in range(4))
    lib.mb_tel_base_twist(_c_params(params), axes.A.size, _doubles(_axis_rows(axes)),
                          _doubles(v), _doubles(w), _doubles(a), _doubles(eps))
    return v, w, a, eps


def reference_pose(params, axes):
    """Subreflector pose the hexapod follows in {B}, (n, 6), with its first and second
    time derivatives: home + (0, Δy(E), Δz(E), 0, 0, 0), Δ = a + b sin E + c cos E
    (the usual gravity-deformation form, ALMA memo 293; coefficients assumed)."""
    pose, rate, acc = (np.empty((axes.A.size, 6)) for _ in range(3))
    lib.mb_tel_reference_pose(_c_params(params), axes.A.size, _doubles(_axis_rows(axes)),
                              _doubles(pose), _doubles(rate), _doubles(acc))
    return pose, rate, acc


# --- the antenna's own axis servo -------------------------------------------------------

def fmu_outputs(params, profile, t):
    """``telescope_outputs`` plus 20 columns, (n, 60): command_base_pose, command_base_rate,
    command_base_acc (equal to the base's: no servo) and axis_acc (Az'', E'')."""
    t = np.ascontiguousarray(t, dtype=float)
    rows, bad = np.empty((t.size, 60)), ffi.new("int *")
    status = lib.mb_tel_fmu_rows_full(_c_params(params), profile, t.size, _doubles(t), _doubles(rows), bad)
    if status:
        raise _status_error(status, profile, t, bad[0])
    return rows


def profile_axes(params, profile, t):
    """(n, 6) command axes [A, A', A'', E, E', E''] of ``profile`` at times t (unchecked
    order: the FMU asks one time at a time)."""
    t = np.ascontiguousarray(np.atleast_1d(t), dtype=float)
    axes, bad = np.empty((t.size, 6)), ffi.new("int *")
    status = lib.mb_tel_axes(_c_params(params), profile, t.size, _doubles(t), _doubles(axes), bad)
    if status:
        raise _status_error(status, profile, t, bad[0])
    return axes


def check_servo(bandwidth, damping):
    """InvalidInputError unless bandwidth [Hz] > 0 and damping [1] > 0, both finite."""
    for name, value in (("servo_bandwidth", bandwidth), ("servo_damping", damping)):
        if not (np.isfinite(value) and value > 0):
            raise InvalidInputError(f"{name} must be finite and > 0, got {value!r}")


SERVO_MAX_WH = 0.05   # w h of one servo RK4 substep, as plant/c/telescope.c takes it


def servo_advance(bandwidth, damping, h, command0, command1, state):
    """Advance the servo state (A, A', E, E') in place over a step h [s] from the command
    axes row ``command0`` to ``command1`` (mb_tel_servo_advance: RK4 with the command's
    cubic Hermite interpolant between the samples). WorkBoundError if the step takes more
    than MAX_SUBSTEPS substeps (the C counts them in an int)."""
    substep_count(h, SERVO_MAX_WH / (2 * math.pi * bandwidth))
    lib.mb_tel_servo_advance(bandwidth, damping, h, _doubles(command0), _doubles(command1), _doubles(state))


def servo_row(params, profile, bandwidth, damping, t, command, state):
    """The telescope FMU's 60 outputs at time t with the servo on (mb_tel_servo_row)."""
    row = np.empty(60)
    lib.mb_tel_servo_row(_c_params(params), profile, bandwidth, damping, t, _doubles(command),
                         _doubles(state), _doubles(row))
    return row


def axis_servo(axes, bandwidth, damping):
    """The actual axes of an antenna whose axis servo (bandwidth [Hz], damping [1]) follows
    the commanded ``axes`` (an AxisMotion): each angle through w^2 / (s^2 + 2 zeta w s +
    w^2), w = 2 pi bandwidth, starting on the command at axes.t[0] (angle and rate), and
    integrated between the samples as the telescope FMU does (servo_advance)."""
    check_servo(bandwidth, damping)
    command = _axis_rows(axes)
    if len(axes.t) > 1:
        substep_count(float(np.max(np.diff(axes.t))), SERVO_MAX_WH / (2 * math.pi * bandwidth))
    state = np.ascontiguousarray(command[0, [0, 1, 3, 4]])
    actual = np.empty_like(command)
    cmd_c, state_c, out = _doubles(command), _doubles(state), _doubles(actual)
    for i in range(command.shape[0]):
        if i:
            lib.mb_tel_servo_advance(bandwidth, damping, axes.t[i] - axes.t[i - 1], cmd_c + 6 * (i - 1),
                                     cmd_c + 6 * i, state_c)
        lib.mb_tel_servo_axes(bandwidth, damping, cmd_c + 6 * i, state_c, out + 6 * i)
    return AxisMotion(axes.t, *actual.T.copy())


# --- the flexible feed support ------------------------------------------------------------

SUPPORT_MODES = 2   # mb_tel_support.mode


def support(frequency, damping, modal_mass, participation, shapes, load_gain=1.0, load_point=(0.0,) * 3,
            preload=(0.0,) * 6):
    """The quadripod's sway modes (plant/c/telescope.h, mb_tel_support: law and assumptions) as
    an mb_tel_support: per mode (SUPPORT_MODES each) the frequency [Hz, 0 = off], damping
    ratio [1, in [0, 1)], modal mass [kg], participation [1] and shape (6: the base's
    translation [m/m] and rotation [rad/m] in {B} per unit modal coordinate); the load's
    gain [1], moment point [m, {B}] and the preload [N, N m] the modes start in equilibrium
    under. InvalidInputError naming the problem."""
    c = ffi.new("mb_tel_support *")
    columns = {"frequency": frequency, "damping": damping, "modal_mass": modal_mass, "participation": participation}
    shapes = _finite("support shapes", shapes)
    if shapes.shape != (SUPPORT_MODES, 6):
        raise InvalidInputError(f"support shapes must be {SUPPORT_MODES} x 6, got shape {shapes.shape}")
    for name, values in columns.items():
        values = np.asarray(values, dtype=float)
        if values.shape != (SUPPORT_MODES,):
            raise InvalidInputError(f"support {name} must hold {SUPPORT_MODES} numbers, got shape {values.shape}")
        for j in range(SUPPORT_MODES):
            setattr(c.mode[j], name, float(values[j]))
    for j in range(SUPPORT_MODES):
        c.mode[j].shape = list(shapes[j])
    c.load_gain, c.load_point, c.preload = float(load_gain), list(map(float, load_point)), list(map(float, preload))
    if lib.mb_tel_support_check(c):
        raise InvalidInputError(ffi.string(lib.mb_tel_status_text(lib.MB_TEL_SUPPORT_RANGE)).decode())
    return c


def support_on(modes):
    """True if a mode of ``modes`` (``support``) is on: otherwise the base is rigid."""
    return bool(lib.mb_tel_support_on(modes))


def support_advance(modes, h, load, state, row, sway):
    """Advance the support's ``state`` (6) over h [s] under the wrench ``load`` (6, held) and add
    its motion to the telescope's ``row`` (columns 0..17, in place; sway (6) gets the modal
    displacement in {B}); h = None: the start, in equilibrium under the preload
    (mb_tel_support_start / _step). Arguments are cffi double* (hot path) or contiguous float64
    arrays (written in place)."""
    ptr = [a if isinstance(a, ffi.CData) else _doubles(a) for a in (load, state, row, sway)]
    status = (lib.mb_tel_support_start(modes, *ptr) if h is None else lib.mb_tel_support_step(modes, h, *ptr))
    if status:
        raise InvalidInputError("support_load input contains NaN or inf")
