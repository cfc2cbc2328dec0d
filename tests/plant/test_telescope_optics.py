"""plant/telescope/optics.py against its independent truths: a ray trace of the Cassegrain
(feed -> displaced hyperboloid -> paraboloid -> aperture plane, each reflection solved
exactly) for the beam direction and the path-length error, Lo's published beam-deviation
factor, Nikolic et al.'s axial path-length formula, and Ruze's law itself."""
import dataclasses
import math

import numpy as np
import pytest

from plant.errors import InvalidInputError
from plant.rotations import rpy_matrix
from plant.telescope import optics
from plant.telescope.optics import ARCSEC, Cassegrain

TIANMA = Cassegrain.tianma()


# ---------------------------------------------------------------- the ray trace
def _reflect(direction, normal):
    normal = normal / np.linalg.norm(normal, axis=1)[:, None]
    return direction - 2.0 * np.sum(direction * normal, axis=1)[:, None] * normal


def _roots(qa, qb, qc):
    """Both roots (n, 2) of qa t^2 + qb t + qc."""
    disc = np.sqrt(qb * qb - 4 * qa * qc)
    return np.stack([(-qb - disc) / (2 * qa), (-qb + disc) / (2 * qa)], axis=1)


def _first_root(roots):
    """The smallest positive root of each row (inf if none)."""
    roots = np.where(roots > 1e-9, roots, np.inf)
    return roots.min(axis=1)


def ray_trace(geometry, motion, n_r=150, n_phi=96):
    """Trace rays from the fixed feed through the subreflector moved by ``motion`` [dx, dy, dz,
    ax, ay] (about the platform origin) and the paraboloid to the plane z = f + 2 m.
    Returns the aperture points (n, 2), each ray's optical path [m] to that plane, its
    illumination weight and its outgoing direction (n, 3)."""
    f, feed, vertex = geometry.points()
    c, a = geometry.semi_axes
    inner, outer = geometry.subreflector_diameter / 2, geometry.diameter / 2
    r = inner + (outer - inner) * (np.arange(n_r) + 0.5) / n_r          # midpoint rule, not Gauss
    phi = 2 * np.pi * (np.arange(n_phi) + 0.25) / n_phi
    r, phi = np.repeat(r, n_phi), np.tile(phi, n_r)
    pedestal = 10 ** (-geometry.edge_taper_db / 20)
    weight = r * (pedestal + (1 - pedestal) * (1 - (r / outer) ** 2))
    psi = 2 * np.arctan(r / (2 * f * geometry.magnification))          # tan(psi/2) = tan(theta/2) / M
    start = np.array([0.0, 0.0, feed])
    direction = np.stack([np.sin(psi) * np.cos(phi), np.sin(psi) * np.sin(phi), np.cos(psi)], axis=1)
    # into the subreflector's own frame: world = o + R (local - o) + d
    d, (ax, ay) = np.asarray(motion[:3], dtype=float), motion[3:]
    pivot = np.array([0.0, 0.0, vertex - geometry.vertex])
    R = rpy_matrix(np.array([ax, ay, 0.0]))
    local_start = pivot + (start - d - pivot) @ R          # R^T (x) as a row vector times R
    local_dir = direction @ R
    zc, b2 = f - c, c * c - a * a                          # (z - zc)^2 / a^2 - rho^2 / b^2 = 1
    s, u = local_start - np.array([0.0, 0.0, zc]), local_dir
    qa = u[:, 2] ** 2 / a**2 - (u[:, 0] ** 2 + u[:, 1] ** 2) / b2
    qb = 2 * (s[2] * u[:, 2] / a**2 - (s[0] * u[:, 0] + s[1] * u[:, 1]) / b2)
    qc = np.full_like(qa, s[2] ** 2 / a**2 - (s[0] ** 2 + s[1] ** 2) / b2 - 1)
    roots = _roots(qa, qb, qc)     # the quadric's other sheet (around the feed) is no mirror
    t1 = _first_root(np.where(local_start[2] + roots * local_dir[:, 2:] > zc, roots, np.inf))
    hit = local_start + t1[:, None] * local_dir
    rel = hit - np.array([0.0, 0.0, zc])
    out_local = _reflect(local_dir, np.stack([-rel[:, 0] / b2, -rel[:, 1] / b2, rel[:, 2] / a**2], axis=1))
    P = pivot + (hit - pivot) @ R.T + d
    out = out_local @ R.T
    # the paraboloid x^2 + y^2 = 4 f z
    qa = out[:, 0] ** 2 + out[:, 1] ** 2
    qb = 2 * (P[:, 0] * out[:, 0] + P[:, 1] * out[:, 1]) - 4 * f * out[:, 2]
    qc = P[:, 0] ** 2 + P[:, 1] ** 2 - 4 * f * P[:, 2]
    t2 = _first_root(_roots(qa, qb, qc))
    Q = P + t2[:, None] * out
    final = _reflect(out, np.stack([2 * Q[:, 0], 2 * Q[:, 1], -4 * f * np.ones(len(Q))], axis=1))
    t3 = (f + 2.0 - Q[:, 2]) / final[:, 2]
    aperture = (Q + t3[:, None] * final)[:, :2]
    return aperture, t1 + t2 + t3, weight, final


def _fit(aperture, path, weight):
    """Weighted least-squares plane path = p0 + gx x + gy y: (gx, gy) and the RMS residual."""
    basis = np.column_stack([np.ones(len(path)), aperture])
    root = np.sqrt(weight)
    coef = np.linalg.lstsq(basis * root[:, None], path * root, rcond=None)[0]
    residual = path - basis @ coef
    return coef[1:], math.sqrt(np.sum(weight * residual**2) / np.sum(weight))


def _traced(geometry, motion):
    """Beam direction (transmit: the path's gradient over the aperture) and path-length
    error of the motion's linear part (a symmetric difference of two traces)."""
    motion = np.asarray(motion, dtype=float)
    plus, minus = ray_trace(geometry, motion), ray_trace(geometry, -motion)
    aperture, _, weight, _ = ray_trace(geometry, np.zeros(5))
    return _fit(aperture, (plus[1] - minus[1]) / 2, weight)


def test_the_undisplaced_antenna_focuses_every_ray():
    """The geometry (the rim condition, the hyperboloid, tan(psi/2) = tan(theta/2)/M) is a
    Cassegrain: every ray leaves along the axis with the same path, to 1e-12 m."""
    aperture, path, _, final = ray_trace(TIANMA, np.zeros(5))
    assert np.ptp(path) < 1e-9
    assert np.max(np.hypot(final[:, 0], final[:, 1])) < 1e-12
    assert np.max(np.hypot(*aperture.T)) == pytest.approx(TIANMA.diameter / 2, rel=5e-3)   # the last midpoint


MOTIONS = {"lateral x": [1e-5, 0, 0, 0, 0], "lateral y": [0, 1e-5, 0, 0, 0], "axial": [0, 0, 1e-5, 0, 0],
           "tilt x": [0, 0, 0, 1e-6, 0], "tilt y": [0, 0, 0, 0, 1e-6],
           "mixed": [3e-6, -2e-6, 4e-6, 5e-7, -3e-7]}


@pytest.mark.parametrize("geometry", [TIANMA, dataclasses.replace(TIANMA, vertex=0.8, magnification=12.0,
                                                                      edge_taper_db=0.0)], ids=["tianma", "other"])
@pytest.mark.parametrize("name", MOTIONS)
def test_pointing_and_path_error_against_the_ray_trace(geometry, name):
    motion = np.array(MOTIONS[name])
    direction, rms = _traced(geometry, motion)
    beam = optics.pointing(motion, geometry)[0]
    assert np.allclose(beam, direction, rtol=1e-4, atol=1e-14)   # rad: an axial offset turns no beam
    assert optics.path_error(motion, geometry)[0] == pytest.approx(rms, rel=1e-4)


def test_a_lateral_offset_against_lo_and_ruzes_beam_deviation_factor():
    """A lateral offset d turns the beam by (BDF - 1/M) d / f: the primary's BDF (Lo 1960's
    fit of Ruze 1965, k = 0.36 for a 10-12 dB taper) less the feed's own 1/M (the image of
    the feed moves by d less d/M). Lo's fit and the integral agree within 2 %; the
    figure for Tianma: 6.1 arcsec per mm."""
    per_mm = -optics.pointing([1e-3, 0, 0, 0, 0], TIANMA)[0, 0] / ARCSEC
    f, m = TIANMA.focal_length, TIANMA.magnification
    published = (optics.beam_deviation_factor(f / TIANMA.diameter) - 1 / m) * 1e-3 / f / ARCSEC
    assert per_mm == pytest.approx(published, rel=0.02)
    assert 6.0 < per_mm < 6.3


def test_an_axial_offset_gives_nikolic_et_als_path_change():
    """Nikolic, Hills & Richer 2007 eq. 3: d_z ((1 - a^2)/(1 + a^2) + (1 - b^2)/(1 + b^2)),
    a = r / 2f, b = r / 2Mf, ray by ray."""
    r = np.linspace(3.3, 32.5, 50)
    phi = np.linspace(0, 6, 50)
    f, m = TIANMA.focal_length, TIANMA.magnification
    a, b = r / (2 * f), r / (2 * m * f)
    published = (1 - a**2) / (1 + a**2) + (1 - b**2) / (1 + b**2)
    assert np.allclose(optics.path_sensitivities(TIANMA, r, phi)[:, 2], published, rtol=1e-12)


def test_subreflector_motion_of_known_poses():
    ref = np.array([0.01, -0.02, -2.68, 0.0, 0.0, 0.3])
    pose = ref + [1e-4, -2e-4, 3e-4, 0, 0, 0]
    assert np.allclose(optics.subreflector_motion(pose, ref), [[1e-4, -2e-4, 3e-4, 0, 0]], atol=1e-15)
    tilted = np.array([0, 0, 0, 2e-5, -1e-5, 0.0])
    assert np.allclose(optics.subreflector_motion(tilted, np.zeros(6)), [[0, 0, 0, 2e-5, -1e-5]], rtol=1e-9)
    # a rotation about the boresight (yaw) costs nothing: the subreflector is symmetric
    assert np.allclose(optics.subreflector_motion([0, 0, 0, 0, 0, 0.01], np.zeros(6)), 0.0, atol=1e-18)
    with pytest.raises(InvalidInputError, match="pose must be a pose"):
        optics.subreflector_motion(np.zeros(5), np.zeros(6))
    with pytest.raises(InvalidInputError, match="reference must be finite"):
        optics.subreflector_motion(np.zeros(6), [0, 0, math.nan, 0, 0, 0])


def test_ruze_exact_values_and_limits():
    lam = 0.01
    assert optics.ruze(0.0, lam) == 1.0
    assert optics.ruze(lam / (4 * math.pi), lam) == pytest.approx(math.exp(-1), rel=1e-15)
    assert optics.ruze(lam / 20, lam) == pytest.approx(math.exp(-(math.pi / 5) ** 2), rel=1e-15)
    assert optics.ruze(1.0, lam) == 0.0                                   # a rough reflector reflects nothing
    assert optics.ruze(1e-9, lam) == pytest.approx(1 - (4 * math.pi * 1e-7) ** 2, rel=1e-15)  # small: quadratic
    # the loss at a band: half the path-length error is the surface error
    assert optics.efficiency_loss(2 * lam / (4 * math.pi), optics.SPEED_OF_LIGHT / lam) == pytest.approx(
        1 - math.exp(-1), rel=1e-12)
    for bad in (-1e-6, math.nan, math.inf):
        with pytest.raises(InvalidInputError, match="sigma"):
            optics.ruze(bad, lam)
    for bad in (0.0, -1.0, math.nan):
        with pytest.raises(InvalidInputError, match="wavelength"):
            optics.ruze(1e-6, bad)


def test_bands_are_tianmas_receivers():
    assert optics.BANDS["K"] == 22e9 and optics.BANDS["Q"] == 43e9
    assert min(optics.BANDS.values()) == 1.4e9 and max(optics.BANDS.values()) == 43e9


@pytest.mark.parametrize("field, value, message", [
    ("magnification", 1.0, "magnification must be > 1"), ("diameter", -1.0, "diameter must be > 0"),
    ("subreflector_diameter", 70.0, "subreflector_diameter must be smaller"),
    ("focal_length", math.nan, "focal_length must be a finite number"),
    ("edge_taper_db", -3.0, "edge_taper_db must be >= 0")])
def test_bad_geometry_is_refused(field, value, message):
    with pytest.raises(InvalidInputError, match=message):
        dataclasses.replace(TIANMA, **{field: value})
