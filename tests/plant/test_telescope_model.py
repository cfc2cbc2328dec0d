"""plant/telescope/model.py against independent truths: astropy's AltAz frame, finite
differences of positions, the rotation-matrix derivative, hand-computed profile
durations and the spherical-trigonometry keyhole law."""
import dataclasses
from datetime import datetime, timedelta

import numpy as np
import pytest
from astropy.utils import iers

iers.conf.auto_download = False          # offline: the IERS tables bundled with astropy
import astropy.units as u  # noqa: E402
from astropy.coordinates import TETE, AltAz, EarthLocation, SkyCoord  # noqa: E402
from astropy.time import Time  # noqa: E402

from plant.telescope.model import (  # noqa: E402
    EARTH_RATE,
    AxisMotion,
    TelescopeParams,
    base_motion,
    base_twist,
    local_sidereal_time,
    near_zenith_source,
    paper_manoeuvre,
    reference_pose,
    sidereal_track,
    slew,
    slew_duration,
)

P = TelescopeParams.tianma()
DEG = np.pi / 180
UTC = datetime(2024, 3, 1, 12, 0, 0)     # inside the bundled IERS tables


def rot_z(a):
    c, s, z, o = np.cos(a), np.sin(a), np.zeros_like(a), np.ones_like(a)
    return np.stack([c, -s, z, s, c, z, z, z, o], axis=-1).reshape(a.shape + (3, 3))


def rot_x(a):
    c, s, z, o = np.cos(a), np.sin(a), np.zeros_like(a), np.ones_like(a)
    return np.stack([o, z, z, z, c, -s, z, s, c], axis=-1).reshape(a.shape + (3, 3))


def R_WB(axes):
    """The spec's base orientation, built by hand: Rz(A) @ Rx(90 deg - E)."""
    return rot_z(axes.A) @ rot_x(np.pi / 2 - axes.E)


def vee(M):
    return np.stack([M[..., 2, 1], M[..., 0, 2], M[..., 1, 0]], axis=-1)


# --- scenarios used by the derivative tests: (profile of t, step h) ------------------

def _slew(t):
    return slew(P, (10 * DEG, 60 * DEG), (100 * DEG, 20.2 * DEG), t)


def _keyhole(t):
    ra, dec = near_zenith_source(P, UTC)
    return sidereal_track(P, ra, dec, UTC - timedelta(seconds=300), t)


def _track(t):
    return sidereal_track(P, 1.0, 10 * DEG, UTC, t)


SCENARIOS = {   # profile, times, finite-difference step h
    "slew": (_slew, np.linspace(0, 190, 1901), 1e-3),     # hits the switch times
    "keyhole": (_keyhole, np.linspace(0, 600, 401), 0.1),
    "track": (_track, np.linspace(0, 7200, 101), 1.0),
    "paper": (paper_manoeuvre, np.linspace(0.01, 5.99, 301), 1e-3),
}


@pytest.fixture(params=list(SCENARIOS))
def samples(request):
    """(motion at t - h, t, t + h, h, mask of points where the profile is smooth)."""
    profile, t, h = SCENARIOS[request.param]
    m0, m1, m2 = profile(t - h), profile(t), profile(t + h)
    smooth = np.ones(t.shape, dtype=bool)
    if request.param == "slew":   # keep the stencils that stay on one acceleration piece
        smooth = (m0.A_ddot == m2.A_ddot) & (m0.E_ddot == m2.E_ddot)
    return m0, m1, m2, h, smooth


def fd(f0, f1, f2, h):
    """First and second central differences."""
    return (f2 - f0) / (2 * h), (f2 - 2 * f1 + f0) / h**2


def assert_close(analytic, numeric, smooth, rtol=1e-5):
    scale = np.max(np.abs(numeric[smooth])) + 1e-12
    np.testing.assert_allclose(analytic[smooth], numeric[smooth], rtol=0, atol=rtol * scale)


# --- astropy ---------------------------------------------------------------------

def _astropy_altaz(ra, dec_deg, t):
    """astropy's (alt, az) [rad] of a source (apparent ra, dec) seen from Tianma at UTC + t."""
    location = EarthLocation.from_geodetic(121.14 * u.deg, 31.09 * u.deg, 0 * u.m)
    start = Time(UTC, scale="utc")
    source = SkyCoord(ra * u.rad, dec_deg * u.deg, frame=TETE(obstime=start))
    altaz = source.transform_to(AltAz(obstime=start + t * u.s, location=location,
                                      pressure=0 * u.hPa))   # no refraction
    return altaz.alt.rad, altaz.az.rad


def _boresight_against_astropy(axes, alt, az):
    """Largest angle [deg] between the base's boresight R_WB e_z in {W} = (east, north,
    up) and astropy's direction, and the largest azimuth difference on the sky [deg]."""
    ours = R_WB(axes)[..., :, 2]
    truth = np.stack([np.cos(alt) * np.sin(az), np.cos(alt) * np.cos(az), np.sin(alt)], axis=-1)
    separation = np.degrees(np.arccos(np.clip(np.sum(ours * truth, axis=-1), -1, 1)))
    daz = np.angle(np.exp(1j * (axes.azimuth - az)))
    return separation.max(), np.degrees(np.abs(daz) * np.cos(alt)).max()


@pytest.mark.parametrize("dec_deg", [-30.0, 0.0, 20.0, 31.0, 60.0, 85.0])
def test_sidereal_track_matches_astropy_altaz(dec_deg):
    """Agreement achieved: <= 0.0013 deg on the sky (GMST in place of apparent sidereal
    time, UTC in place of UT1, aberration and polar motion left out); asserted < 0.003.
    The truth is the direction the base's boresight points, not only the angles."""
    ra = local_sidereal_time(P, UTC) + 0.3          # transits ~70 min after the start
    t = np.linspace(0, 3 * 3600, 181)
    axes = sidereal_track(P, ra, dec_deg * DEG, UTC, t)
    alt, az = _astropy_altaz(ra, dec_deg, t)
    separation, azimuth = _boresight_against_astropy(axes, alt, az)
    assert separation < 0.003 and azimuth < 0.003
    assert np.degrees(np.abs(axes.E - alt)).max() < 0.003


@pytest.mark.parametrize("hour_angle_h, side", [(-2.0, "east"), (2.0, "west")])
def test_source_east_and_west_of_the_meridian_against_astropy(hour_angle_h, side):
    """A source 2 h before transit stands in the east (astropy Az in (0, 180) deg), 2 h
    after in the west: the base's boresight points there ({W} x east, y north), the
    mount angle is A = 180 deg - Az, and the azimuth rate has the sky's sign (the Az of a
    source south of the zenith grows through the day)."""
    ra = local_sidereal_time(P, UTC) - hour_angle_h * np.pi / 12
    t = np.linspace(0, 600, 11)
    axes = sidereal_track(P, ra, 10.0 * DEG, UTC, t)
    alt, az = _astropy_altaz(ra, 10.0, t)
    assert np.all((np.degrees(az) < 180) == (side == "east"))
    separation, azimuth = _boresight_against_astropy(axes, alt, az)
    assert separation < 0.003 and azimuth < 0.003
    assert np.all(np.sign(R_WB(axes)[:, 0, 2]) == (1 if side == "east" else -1))   # east component
    np.testing.assert_allclose(axes.A, np.pi - axes.azimuth)
    daz_dt = np.angle(np.exp(1j * np.diff(az))) / np.diff(t)
    np.testing.assert_allclose(-(axes.A_dot[:-1] + axes.A_dot[1:]) / 2, daz_dt, rtol=1e-3)


def test_slew_targets_are_astronomical():
    """A slew to Az 90 deg (east) at el 0 points the boresight east, to Az 0 north."""
    for az, direction in ((90.0, [1, 0, 0]), (0.0, [0, 1, 0]), (180.0, [0, -1, 0])):
        axes = slew(P, (az * DEG, 0.0), (az * DEG, 0.0), np.zeros(1))
        np.testing.assert_allclose(R_WB(axes)[0, :, 2], direction, atol=1e-12)
        pose, _, _ = base_motion(P, axes)
        np.testing.assert_allclose(pose[0, :3], P.lever_arm * np.array(direction), atol=1e-12)


# --- derivatives against finite differences ----------------------------------------

def test_axis_derivatives(samples):
    m0, m1, m2, h, smooth = samples
    for name in ("A", "E"):
        rate, acc = fd(getattr(m0, name), getattr(m1, name), getattr(m2, name), h)
        assert_close(getattr(m1, name + "_dot"), rate, smooth)
        assert_close(getattr(m1, name + "_ddot"), acc, smooth, rtol=1e-4)


def test_base_pose_derivatives(samples):
    m0, m1, m2, h, smooth = samples
    (q0, _, _), (q1, rate, acc), (q2, _, _) = (base_motion(P, m) for m in (m0, m1, m2))
    rate_fd, acc_fd = fd(q0, q1, q2, h)
    assert_close(rate, rate_fd, smooth)
    assert_close(acc, acc_fd, smooth, rtol=1e-4)


def test_base_twist_against_rotation_derivative(samples):
    """skew(w_B) = R^T dR/dt, skew(eps_B) = antisymmetric part of R^T d2R/dt2,
    v_B = R^T dp/dt, a_B = R^T d2p/dt2, with R built by hand from Rz(A) Rx(90 - E)."""
    m0, m1, m2, h, smooth = samples
    R0, R1, R2 = R_WB(m0), R_WB(m1), R_WB(m2)
    R_dot, R_ddot = fd(R0, R1, R2, h)
    Rt = np.swapaxes(R1, -1, -2)
    p0, p1, p2 = (base_motion(P, m)[0][:, :3] for m in (m0, m1, m2))
    p_dot, p_ddot = fd(p0, p1, p2, h)
    v, w, a, eps = base_twist(P, m1)

    assert_close(w, vee(Rt @ R_dot), smooth)
    S = Rt @ R_ddot
    assert_close(eps, vee(0.5 * (S - np.swapaxes(S, -1, -2))), smooth, rtol=1e-4)
    assert_close(v, (Rt @ p_dot[..., None])[..., 0], smooth)
    assert_close(a, (Rt @ p_ddot[..., None])[..., 0], smooth, rtol=1e-4)
    skew_w = Rt @ R_dot                                  # and it is a skew matrix
    np.testing.assert_allclose(skew_w + np.swapaxes(skew_w, -1, -2), 0, atol=1e-7)


def test_reference_pose_derivatives(samples):
    m0, m1, m2, h, smooth = samples
    (r0, _, _), (r1, rate, acc), (r2, _, _) = (reference_pose(P, m) for m in (m0, m1, m2))
    rate_fd, acc_fd = fd(r0, r1, r2, h)
    assert_close(rate, rate_fd, smooth)
    assert_close(acc, acc_fd, smooth, rtol=1e-4)


# --- conventions, by hand -------------------------------------------------------------

def test_base_pose_follows_spec_convention():
    A, E = np.array([0.0, 0.0, 30 * DEG, 200 * DEG]), np.array([90, 0, 45, 10]) * DEG
    zero = np.zeros_like(A)
    axes = AxisMotion(np.arange(4.0), A, zero, zero, E, zero, zero)
    pose, _, _ = base_motion(P, axes)
    R = R_WB(axes)
    np.testing.assert_allclose(pose[:, :3], R @ [0, 0, P.lever_arm], atol=1e-12)
    np.testing.assert_allclose(pose[:, 3:], np.column_stack([np.pi / 2 - E, zero, A]))
    np.testing.assert_allclose(pose[0], [0, 0, 25, 0, 0, 0], atol=1e-12)     # zenith
    np.testing.assert_allclose(pose[1], [0, -25, 0, np.pi / 2, 0, 0], atol=1e-12)


def test_reference_pose_values():
    zero = np.zeros(2)
    axes = AxisMotion(np.arange(2.0), zero, zero, zero, np.array([90, 0]) * DEG, zero, zero)
    pose, _, _ = reference_pose(P, axes)
    np.testing.assert_allclose(pose[0], [0, 0, -2.6815, 0, 0, 0], atol=1e-15)   # home at zenith
    np.testing.assert_allclose(pose[1], [0, 0.020, -2.6815 + 0.015, 0, 0, 0], atol=1e-15)


def test_paper_manoeuvre_end_points():
    axes = paper_manoeuvre(np.array([-1.0, 0.0, 3.0, 6.0, 7.0]))
    np.testing.assert_allclose(np.degrees(axes.A), [0, 0, 15, 30, 30], atol=1e-12)
    np.testing.assert_allclose(np.degrees(axes.E), [90, 90, 67.5, 45, 45], atol=1e-12)
    for rate in (axes.A_dot, axes.E_dot, axes.A_ddot, axes.E_ddot):
        np.testing.assert_allclose(rate[[0, 1, 3, 4]], 0, atol=1e-15)
    assert np.degrees(abs(axes.E_dot[2])) == pytest.approx(45 * 1.875 / 6)   # 14.1 deg/s
    pose, _, _ = base_motion(dataclasses.replace(P, lever_arm=0.0), axes)
    np.testing.assert_allclose(pose[3], [0, 0, 0, np.pi / 4, 0, np.pi / 6], atol=1e-12)


# --- slew -------------------------------------------------------------------------

@pytest.mark.parametrize("start, target, expected", [
    ((0, 30), (90, 30), 90 / 0.5 + 0.5 / 0.25),          # azimuth trapezoid: 182 s
    ((0, 30), (0, 70), 40 / 0.3 + 0.3 / 0.25),           # elevation trapezoid
    ((0, 30), (0, 30.2), 2 * np.sqrt(0.2 / 0.25)),       # elevation triangle (< 0.36 deg)
    ((50, 30), (49.9, 30), 2 * np.sqrt(0.1 / 0.25)),     # azimuth triangle, backwards
    ((0, 30), (90, 70), 90 / 0.5 + 0.5 / 0.25),          # both: the slower axis decides
    ((0, 30), (0, 30), 0.0),
])
def test_slew_duration_and_limits(start, target, expected):
    start, target = np.radians(start), np.radians(target)
    duration = slew_duration(P, start, target)
    assert duration == pytest.approx(expected, rel=1e-12, abs=1e-12)
    t = np.linspace(-1, duration + 5, 20001)
    axes = slew(P, start, target, t)
    assert np.max(np.abs(axes.A_dot)) <= P.az_rate_max * (1 + 1e-12)
    assert np.max(np.abs(axes.E_dot)) <= P.el_rate_max * (1 + 1e-12)
    assert np.max(np.abs(axes.A_ddot)) <= P.az_acc_max * (1 + 1e-12)
    assert np.max(np.abs(axes.E_ddot)) <= P.el_acc_max * (1 + 1e-12)
    # the integral of the rate is the distance travelled (trapezoid rule, exact enough)
    A_travel = np.sum(0.5 * (axes.A_dot[1:] + axes.A_dot[:-1]) * np.diff(t))
    assert -A_travel == pytest.approx(target[0] - start[0], abs=1e-6)     # A = 180 deg - Az
    done = t >= duration
    np.testing.assert_allclose(axes.azimuth[done], target[0], atol=1e-12)
    np.testing.assert_allclose(axes.E[done], target[1], atol=1e-12)
    np.testing.assert_allclose(axes.A_dot[done], 0)
    np.testing.assert_allclose(axes.E_dot[done], 0)
    np.testing.assert_allclose([axes.azimuth[0], axes.E[0]], start)    # held before 0
    if duration > 0:
        just_before = slew(P, start, target, duration - 1e-3)
        assert abs(just_before.A_dot[0]) + abs(just_before.E_dot[0]) > 0


# --- keyhole and azimuth continuity ------------------------------------------------

def test_keyhole_azimuth_rate_grows_as_one_over_cos_E():
    """At transit a source `miss` south of the zenith has A_dot cos E = Omega cos(dec)."""
    peaks = []
    for miss_deg in (2.0, 1.0, 0.5, 0.2, 0.1):
        ra, dec = near_zenith_source(P, UTC, miss_deg * DEG)
        t = np.linspace(0, 1200, 2401)                                   # transit at 600 s
        axes = sidereal_track(P, ra, dec, UTC - timedelta(seconds=600), t)
        i = np.argmax(np.abs(axes.A_dot))
        assert t[i] == pytest.approx(600, abs=1)
        assert np.degrees(axes.E[i]) == pytest.approx(90 - miss_deg, abs=1e-5)
        assert abs(axes.A_dot[i]) * np.cos(axes.E[i]) == pytest.approx(EARTH_RATE * np.cos(dec),
                                                                         rel=1e-5)
        peaks.append(abs(axes.A_dot[i]))
    assert peaks[0] < P.az_rate_max < peaks[3]          # 2 deg: fine; 0.2 deg: keyhole
    growth = np.sin(2 * DEG) * np.cos(P.latitude - 0.1 * DEG) / np.cos(P.latitude - 2 * DEG)
    assert peaks[4] / peaks[0] == pytest.approx(growth / np.sin(0.1 * DEG), rel=1e-4)


@pytest.mark.parametrize("dec_deg, hours", [(20.0, 8), (31.0, 2), (70.0, 24)])
def test_azimuth_is_continuous_whatever_the_sampling(dec_deg, hours):
    """Through the south (atan2's branch cut; 31 deg passes 0.09 deg from the zenith) and
    around the north: sparse samples, one at a time, lie on the densely sampled curve."""
    ra = local_sidereal_time(P, UTC) + 0.5
    dense_t = np.linspace(0, hours * 3600, 96 * 1000 + 1)
    dense = sidereal_track(P, ra, dec_deg * DEG, UTC, dense_t).A
    assert 0 <= dense[0] < 2 * np.pi
    assert np.max(np.abs(np.diff(dense))) < 0.1
    stepwise = [sidereal_track(P, ra, dec_deg * DEG, UTC, ti).A[0] for ti in dense_t[::1000]]
    np.testing.assert_allclose(stepwise, dense[::1000], atol=1e-9)


# --- bad input ----------------------------------------------------------------------

@pytest.mark.parametrize("change, match", [
    (dict(az_rate_max=-0.01), "az_rate_max"),
    (dict(el_acc_max=0.0), "el_acc_max"),
    (dict(latitude=float("nan")), "latitude"),
    (dict(latitude=2.0), "latitude"),
    (dict(lever_arm=-1.0), "lever_arm"),
    (dict(home=(0, 0, -2.68)), "home"),
])
def test_bad_params_raise(change, match):
    with pytest.raises(ValueError, match=match):
        dataclasses.replace(P, **change)


@pytest.mark.parametrize("call, match", [
    (lambda: slew(P, (0, 30 * DEG), (0, 95 * DEG), [0.0]), "elevation"),
    (lambda: slew(P, (0, -1 * DEG), (0, 30 * DEG), [0.0]), "elevation"),
    (lambda: slew(P, (np.nan, 0.5), (0, 0.5), [0.0]), "start_az_el"),
    (lambda: slew(P, (0, 0.5), (0, 0.6), [0.0, 2.0, 1.0]), "increasing"),
    (lambda: slew(P, (0, 0.5), (0, 0.6), [0.0, np.nan]), "finite"),
    (lambda: paper_manoeuvre([0.0, 0.0]), "increasing"),
    (lambda: paper_manoeuvre([0.0], T=0.0), "T"),
    (lambda: sidereal_track(P, 0.0, -80 * DEG, UTC, [0.0]), "horizon"),
    (lambda: sidereal_track(P, 0.0, P.latitude, UTC, [0.0]), "zenith"),
    (lambda: sidereal_track(P, 0.0, 2.0, UTC, [0.0]), "dec"),
    (lambda: sidereal_track(P, 0.0, 0.5, "2024-03-01", [0.0]), "datetime"),
    (lambda: AxisMotion(*[np.zeros(1)] * 4, np.array([1.6]), *[np.zeros(1)] * 2), "elevation"),
])
def test_bad_input_raises(call, match):
    with pytest.raises(ValueError, match=match):
        call()
