"""The telescope that moves the hexapod's base: axis profiles -> base and reference motion.

Law: shared/spec/telescope.md; frames and poses: shared/spec/stewart-6ups.md. SI inside
(m, rad, s); angles are radians in every argument. All functions are vectorised over a
1-D array of times and every derivative is analytic (chain rule), so a consumer never
differences samples.

Pipeline: a profile (``slew``, ``sidereal_track``, ``paper_manoeuvre``) gives the axis
angles A (azimuth), E (elevation) and their first two derivatives as an ``AxisMotion``;
``base_motion`` / ``base_twist`` turn it into the motion of the hexapod's base {B} in
{W}; ``reference_pose`` into the subreflector pose the hexapod must follow in {B}.

Modelling assumptions (beyond the values labelled "assumed" in ``TelescopeParams``):

* {W} is treated as inertial: the Earth's rotation (7.3e-5 rad/s) is left out of the
  base's angular velocity; its centripetal and Coriolis terms on the hexapod are of
  order 1e-8 m/s^2.
* R_WB = Rz(A) Rx(90 deg - E) is used exactly as the spec writes it, with A measured
  north through east. A right-handed {W} with z up then sees the sky mirrored (yaw
  grows anticlockwise from above, astronomical azimuth clockwise); rates and
  accelerations have the same magnitudes either way.
"""
from dataclasses import dataclass
from datetime import datetime, timezone

import numpy as np

from .errors import InvalidInputError
from .rotations import cross
from .trajectory import quintic

EARTH_RATE = 7.2921159e-5           # rad/s, the rate at which the hour angle advances
_J2000 = datetime(2000, 1, 1, 12, tzinfo=timezone.utc)
_E_TOLERANCE = 1e-9                 # rad of rounding allowed outside [0, 90 deg]


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
    """Azimuth A and elevation E (rad) with first and second time derivatives at times t."""

    t: np.ndarray
    A: np.ndarray
    A_dot: np.ndarray
    A_ddot: np.ndarray
    E: np.ndarray
    E_dot: np.ndarray
    E_ddot: np.ndarray

    def __post_init__(self):
        t = _times(self.t)
        for name in ("A", "A_dot", "A_ddot", "E", "E_dot", "E_ddot"):
            value = _finite(name, getattr(self, name))
            if value.shape != t.shape:
                raise InvalidInputError(f"{name} has shape {value.shape}, t has {t.shape}")
            object.__setattr__(self, name, value)
        object.__setattr__(self, "t", t)
        _check_elevation("elevation E", self.E)


# --- slew -------------------------------------------------------------------------

def _trapezoid(distance, rate_max, acc_max, t):
    """Rate- and acceleration-limited move over ``distance`` (signed) starting at t = 0:
    position, rate, acceleration at t, and duration. Triangular when the rate limit is
    never reached (|distance| <= rate_max^2 / acc_max)."""
    D, sign = abs(distance), np.sign(distance)
    t_acc = min(rate_max / acc_max, np.sqrt(D / acc_max))
    peak = acc_max * t_acc
    duration = 0.0 if D == 0 else D / peak + t_acc          # 2 t_acc + cruise time
    t_dec = duration - t_acc                                 # start of braking
    to_go = duration - t
    phases = [t <= 0, t < t_acc, t < t_dec, t < duration]
    s = np.select(phases, [0.0, 0.5 * acc_max * t**2, 0.5 * peak * t_acc + peak * (t - t_acc),
                           D - 0.5 * acc_max * to_go**2], D)
    v = np.select(phases, [0.0, acc_max * t, peak, acc_max * to_go], 0.0)
    a = np.select(phases, [0.0, acc_max, 0.0, -acc_max], 0.0)
    return sign * s, sign * v, sign * a, duration


def _slew_moves(params, start_az_el, target_az_el):
    (A0, E0), (A1, E1) = _finite("start_az_el", start_az_el), _finite("target_az_el", target_az_el)
    _check_elevation("slew elevation", np.array([E0, E1]))
    return ((A0, A1 - A0, params.az_rate_max, params.az_acc_max),
            (E0, E1 - E0, params.el_rate_max, params.el_acc_max))


def slew_duration(params, start_az_el, target_az_el):
    """Seconds until both axes of ``slew`` have arrived (the slower axis decides)."""
    return max(_trapezoid(d, v, a, np.zeros(1))[3]
               for _, d, v, a in _slew_moves(params, start_az_el, target_az_el))


def slew(params, start_az_el, target_az_el, t):
    """Slew from (A, E) to (A, E) [rad], both axes starting at t = 0 with trapezoidal
    profiles at their own limits; holds the start before 0 and the target once arrived.
    The azimuth moves by target - start literally (no shortest way): the cable wrap
    is the caller's choice."""
    t = _times(t)
    (A0, dA, *az), (E0, dE, *el) = _slew_moves(params, start_az_el, target_az_el)
    A, A_dot, A_ddot, _ = _trapezoid(dA, *az, t)
    E, E_dot, E_ddot, _ = _trapezoid(dE, *el, t)
    return AxisMotion(t, A0 + A, A_dot, A_ddot, E0 + E, E_dot, E_ddot)


# --- sidereal tracking ------------------------------------------------------------

def local_sidereal_time(params, utc):
    """Local mean sidereal time (rad, in [0, 2 pi)) at a UTC ``datetime`` (naive = UTC).

    GMST of IAU 1982 (Meeus eq. 12.4) with UTC in place of UT1. Against the apparent
    sidereal time astropy uses this is off by the equation of the equinoxes (<= 1.2 s)
    plus |UT1 - UTC| (<= 0.9 s): <= 0.009 deg of hour angle at worst; the tests measure
    <= 0.0013 deg on the sky against astropy's AltAz in 2024."""
    if not isinstance(utc, datetime):
        raise InvalidInputError(f"utc must be a datetime, got {utc!r}")
    if utc.tzinfo is None:
        utc = utc.replace(tzinfo=timezone.utc)
    days = (utc - _J2000).total_seconds() / 86400.0
    T = days / 36525.0
    gmst = 280.46061837 + 360.98564736629 * days + 0.000387933 * T**2 - T**3 / 38710000.0
    return np.mod(np.radians(gmst) + params.longitude, 2 * np.pi)


def _direction(H, dec, lat):
    """Unit pointing vector (north, east, up) at hour angle H and its two time derivatives."""
    cd, sd, cl, sl = np.cos(dec), np.sin(dec), np.cos(lat), np.sin(lat)
    cH, sH, w = np.cos(H), np.sin(H), EARTH_RATE
    u = (sd * cl - cd * sl * cH, -cd * sH, sl * sd + cl * cd * cH)
    u_dot = (cd * sl * sH * w, -cd * cH * w, -cl * cd * sH * w)
    u_ddot = (cd * sl * cH * w**2, cd * sH * w**2, -cl * cd * cH * w**2)
    return u, u_dot, u_ddot


def _azimuth(H, north, east, dec, lat):
    """Azimuth continuous in H whatever the sampling: atan2 jumps by -2 pi at each upper
    culmination of a source transiting south of the zenith (dec < lat) and by +2 pi at
    each lower culmination of one culminating below the north pole (dec < -lat)."""
    A = np.arctan2(east, north)
    A += 2 * np.pi * (dec < lat) * np.floor(H / (2 * np.pi))
    A -= 2 * np.pi * (dec < -lat) * np.floor((H - np.pi) / (2 * np.pi))
    return A


def sidereal_track(params, ra, dec, utc_start, t):
    """Track a source at apparent (of date) right ascension ``ra`` and declination
    ``dec`` [rad] from ``utc_start`` (a ``datetime``, naive = UTC) at times t [s].

    Catalogue (J2000) coordinates must be precessed first: ~0.35 deg by 2025.
    Azimuth is north through east, continuous (no 2 pi jumps) and in [0, 2 pi) at t = 0,
    so step-by-step callers with the same utc_start see one continuous curve.
    Refraction is ignored."""
    t = _times(t)
    ra, dec = _finite("ra", ra), _finite("dec", dec)
    lat = params.latitude
    if abs(dec) > np.pi / 2:
        raise InvalidInputError(f"dec must lie in [-90, 90] deg, got {np.degrees(dec):.6g} deg")
    if abs(dec - lat) < 1e-6:
        raise InvalidInputError("the source passes through the zenith, where the azimuth is "
                                "undefined; offset dec from the latitude (near_zenith_source)")
    H0 = np.mod(local_sidereal_time(params, utc_start) - ra + np.pi, 2 * np.pi) - np.pi
    H = H0 + EARTH_RATE * t
    (n, e, z), (n1, e1, z1), (n2, e2, z2) = _direction(H, dec, lat)
    cos_E = np.hypot(n, e)
    A_dot = (n * e1 - e * n1) / cos_E**2
    A_ddot = (n * e2 - e * n2) / cos_E**2 - 2 * A_dot * (n * n1 + e * e1) / cos_E**2
    E = np.arctan2(z, cos_E)
    E_dot = z1 / cos_E                                   # from sin E = z
    E_ddot = (z2 + z * E_dot**2) / cos_E
    if np.any(E < 0):
        raise InvalidInputError(f"the source is below the horizon at t = {t[np.argmax(E < 0)]} s")
    (n0, e0, _), _, _ = _direction(H0, dec, lat)
    wraps = np.floor(_azimuth(H0, n0, e0, dec, lat) / (2 * np.pi))
    A = _azimuth(H, n, e, dec, lat) - 2 * np.pi * wraps
    return AxisMotion(t, A, A_dot, A_ddot, E, E_dot, E_ddot)


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
    (roll, yaw), (roll_dot, yaw_dot), (roll_ddot, yaw_ddot) = (
        x.T for x in quintic((0.0, 0.0), np.radians((45.0, 30.0)), T, t))
    return AxisMotion(t, yaw, yaw_dot, yaw_ddot, np.pi / 2 - roll, -roll_dot, -roll_ddot)


# --- what the axes do to the base and to the reference ---------------------------------

def base_motion(params, axes):
    """Pose of {B} in {W} and its plain time derivatives, each (n, 6): roll = 90 deg - E,
    pitch = 0, yaw = A, p_B = R_WB (0, 0, L) = L (cos E sin A, -cos E cos A, sin E)."""
    A, E, zero = axes.A, axes.E, np.zeros_like(axes.A)
    L, cA, sA, cE, sE = params.lever_arm, np.cos(A), np.sin(A), np.cos(E), np.sin(E)
    p = L * np.stack([cE * sA, -cE * cA, sE], axis=-1)
    dp_dE = L * np.stack([-sE * sA, sE * cA, cE], axis=-1)
    dp_dA = L * np.stack([cE * cA, cE * sA, zero], axis=-1)
    d2p_dE2 = L * np.stack([-cE * sA, cE * cA, -sE], axis=-1)
    d2p_dEdA = L * np.stack([-sE * cA, -sE * sA, zero], axis=-1)
    d2p_dA2 = L * np.stack([-cE * sA, cE * cA, zero], axis=-1)
    dA, ddA, dE, ddE = (x[:, None] for x in (axes.A_dot, axes.A_ddot, axes.E_dot, axes.E_ddot))
    p_dot = dp_dE * dE + dp_dA * dA
    p_ddot = (dp_dE * ddE + dp_dA * ddA + d2p_dE2 * dE**2 + 2 * d2p_dEdA * dE * dA
              + d2p_dA2 * dA**2)
    pose = np.column_stack([p, np.pi / 2 - E, zero, A])
    rate = np.column_stack([p_dot, -axes.E_dot, zero, axes.A_dot])
    acc = np.column_stack([p_ddot, -axes.E_ddot, zero, axes.A_ddot])
    return pose, rate, acc


def base_twist(params, axes):
    """(v_B, w_B, a_B, eps_B), each (n, 3) in {B}: velocity and inertial acceleration of
    the base origin, angular velocity and angular acceleration of {B}.

    w_W = A_dot z_W - E_dot Rz(A) x_W; in {B} (R_WB = Rz(A) Rx(r), r = 90 deg - E) that is
    w_B = (-E_dot, A_dot cos E, A_dot sin E), and eps_B = d(w_B)/dt since w_B x w_B = 0.
    The origin sits at l = (0, 0, L) in {B} on the rotating body: v_B = w_B x l,
    a_B = eps_B x l + w_B x (w_B x l)."""
    dA, ddA, dE, ddE = axes.A_dot, axes.A_ddot, axes.E_dot, axes.E_ddot
    cE, sE = np.cos(axes.E), np.sin(axes.E)
    w = np.stack([-dE, dA * cE, dA * sE], axis=-1)
    eps = np.stack([-ddE, ddA * cE - dA * dE * sE, ddA * sE + dA * dE * cE], axis=-1)
    lever = np.broadcast_to([0.0, 0.0, params.lever_arm], w.shape)
    v = cross(w, lever)
    a = cross(eps, lever) + cross(w, v)
    return v, w, a, eps


def reference_pose(params, axes):
    """Subreflector pose the hexapod follows in {B}, (n, 6), with its first and second
    time derivatives: home + (0, Δy(E), Δz(E), 0, 0, 0), Δ = a + b sin E + c cos E
    (the usual gravity-deformation form, ALMA memo 293; coefficients assumed)."""
    E, dE, ddE = axes.E, axes.E_dot, axes.E_ddot
    cE, sE = np.cos(E), np.sin(E)
    pose = np.tile(np.asarray(params.home), (E.size, 1))
    rate, acc = np.zeros_like(pose), np.zeros_like(pose)
    for column, a, b, c in ((1, params.a_y, params.b_y, params.c_y),
                            (2, params.a_z, params.b_z, params.c_z)):
        slope = b * cE - c * sE                       # dΔ/dE
        pose[:, column] += a + b * sE + c * cE
        rate[:, column] = slope * dE
        acc[:, column] = slope * ddE - (b * sE + c * cE) * dE**2
    return pose, rate, acc
