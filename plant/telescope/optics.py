"""The subreflector's pose error in the telescope's units: pointing [rad] and aperture
efficiency (Ruze) per observing band. Law: docs/conventions/telescope.md ("What an error
costs"). SI inside (m, rad, Hz).

The antenna is modelled as the classical Cassegrain equivalent of Tianma's shaped one
(shaping redistributes the illumination; to first order it leaves the focal points and
the ray angles, which the sensitivities below depend on, unchanged): a paraboloid of
focal length f with a hyperboloidal subreflector of magnification M, prime focus F1 and
feed at F2, the optical axis along z_B (the boresight).

A small rigid displacement u(P) of the subreflector changes the path of the ray that
reflects at P by u(P) . (e_in - e_out), e_in and e_out the ray's unit directions before
and after the reflection (Ruze 1969, "Small displacements in parabolic reflectors", MIT
Lincoln Lab.; Baars 2007, "The Paraboloidal Reflector Antenna in Radio Astronomy and
Communication", Springer, ch. 4). For an axial displacement d_z this is d_z (cos theta +
cos psi), theta and psi the ray's angles at F1 and F2: the path-length sensitivity of
Nikolic, Hills & Richer 2007, A&A 465, 679, eq. 3 (out-of-focus holography). Over the
aperture, weighted by the illumination:

* the beam deviation is the least-squares tilt of that path-length error (a plane wave's
  direction); for a lateral displacement d it is (BDF - 1/M) d / f: the primary's
  beam-deviation factor BDF (Lo 1960, IRE Trans. AP-8, 347; Ruze 1965, IEEE Trans. AP-13,
  660, "Lateral-feed displacement in a paraboloid") less the feed's share 1/M (the image
  of the feed moves by d - d/M; the rays at F2 are paraxial, their factor is 1);
* the rest, once the piston and that tilt are removed, is the path-length error sigma
  that costs efficiency by Ruze 1966 (Proc. IEEE 54, 633): exp(-(4 pi sigma_s / lambda)^2)
  with sigma_s the equivalent surface error, half the path-length error (a reflection
  doubles a surface error in path).

Both are linear in the displacement: ``sensitivities`` integrates them once per geometry
(Gauss-Legendre in radius, uniform in azimuth), so a block of poses costs a 5x5 product.
The pointing loss of the beam deviation (a Gaussian beam's exp(-4 ln 2 (dtheta/HPBW)^2))
is not in the efficiency: a pointing error is reported as an angle.
"""
import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from plant.errors import InvalidInputError
from plant.rotations import rpy_matrix

ARCSEC = math.pi / 648000.0          # rad
SPEED_OF_LIGHT = 299_792_458.0       # m/s
# Tianma's receivers, centre frequencies [Hz]: L 1.4, S 2.3, C 6.7, X 8.4, Ku 15, K 22, Ka 31,
# Q 43 GHz (EAVN status report 2018B, "Brief summary of Tianma65 receiving system",
# radio.kasi.re.kr/eavn/status_report18b/node13.html; 1.25-50 GHz in all)
BANDS = {"L": 1.4e9, "S": 2.3e9, "C": 6.7e9, "X": 8.4e9, "Ku": 15e9, "K": 22e9, "Ka": 31e9, "Q": 43e9}
_RADII, _AZIMUTHS = 64, 64           # aperture quadrature: exact for the smooth integrands to ~1e-10


@dataclass(frozen=True)
class Cassegrain:
    """Geometry of the antenna's optics (m) and its illumination. The hyperboloid's
    interfocal distance follows from the rim ray: the subreflector's rim sends the
    primary's rim ray."""

    diameter: float               # primary aperture D
    focal_length: float           # primary focal length f
    magnification: float          # M = (e + 1) / (e - 1): effective focal length M f
    subreflector_diameter: float  # its rim; it also blocks the aperture's centre
    vertex: float                 # subreflector vertex on z_P from the platform origin o_P
    edge_taper_db: float          # illumination at the rim, parabola on a pedestal in amplitude

    def __post_init__(self):
        for name in ("diameter", "focal_length", "subreflector_diameter", "vertex", "edge_taper_db"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise InvalidInputError(f"{name} must be a finite number, got {value!r}")
        for name in ("diameter", "focal_length", "subreflector_diameter"):
            if getattr(self, name) <= 0:
                raise InvalidInputError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if not (math.isfinite(self.magnification) and self.magnification > 1):
            raise InvalidInputError(f"magnification must be > 1 (a Cassegrain), got {self.magnification!r}")
        if not self.subreflector_diameter < self.diameter:
            raise InvalidInputError("subreflector_diameter must be smaller than the diameter")
        if self.edge_taper_db < 0:
            raise InvalidInputError(f"edge_taper_db must be >= 0 dB, got {self.edge_taper_db!r}")

    @classmethod
    def tianma(cls):
        """Shanghai Tianma 65 m. D = 65 m is public; the rest is assumed (no public source
        found): f = 21 m (f/D 0.32, the class of Effelsberg 0.30 and SRT 0.33), M = 8 (a
        feed half-angle of 11 deg), a 6.5 m subreflector (D/10, as Effelsberg's), its vertex
        at the platform origin, a 12 dB edge taper."""
        return cls(diameter=65.0, focal_length=21.0, magnification=8.0, subreflector_diameter=6.5,
                   vertex=0.0, edge_taper_db=12.0)

    @property
    def rim_angle(self):
        """Half-angle the primary subtends at F1 [rad]: tan(theta0 / 2) = D / 4f."""
        return 2.0 * math.atan(self.diameter / (4.0 * self.focal_length))

    @property
    def semi_axes(self):
        """(c, a) of the hyperboloid [m]: c half the interfocal distance, a = c (M-1)/(M+1),
        c from the rim: r1(theta0) sin(theta0) = subreflector radius with r1(theta) =
        (c^2 - a^2) / (a + c cos theta) the distance from F1."""
        m, t0 = self.magnification, self.rim_angle
        c = 0.5 * self.subreflector_diameter * (m + 1) * (m - 1 + (m + 1) * math.cos(t0)) / (4 * m * math.sin(t0))
        return c, c * (m - 1) / (m + 1)

    def points(self):
        """Focus F1, feed F2 and subreflector vertex V on the axis: z [m] from the primary's
        vertex (F1 at f, V at f - (c - a), F2 at f - 2c)."""
        c, a = self.semi_axes
        f = self.focal_length
        return f, f - 2 * c, f - (c - a)


def beam_deviation_factor(focal_ratio, k=0.36):
    """Lo's (1960) fit of Ruze's (1965) beam-deviation factor of a paraboloid of f/D
    ``focal_ratio``: (1 + k (D/4f)^2) / (1 + (D/4f)^2), k = 0.36 for a typical taper. A
    published check on ``sensitivities`` (which integrate the factor for the given
    illumination), not used by it."""
    q = (1.0 / (4.0 * focal_ratio)) ** 2
    return (1.0 + k * q) / (1.0 + q)


def _aperture(optics):
    """Quadrature over the unblocked aperture: radii r, azimuths phi (flattened) and the
    normalised weights (illumination amplitude times area)."""
    inner, outer = 0.5 * optics.subreflector_diameter, 0.5 * optics.diameter
    x, w = np.polynomial.legendre.leggauss(_RADII)
    r = inner + (outer - inner) * 0.5 * (x + 1.0)
    pedestal = 10.0 ** (-optics.edge_taper_db / 20.0)
    amplitude = pedestal + (1.0 - pedestal) * (1.0 - (r / outer) ** 2)
    phi = 2.0 * np.pi * np.arange(_AZIMUTHS) / _AZIMUTHS
    weight = np.repeat(w * r * amplitude, _AZIMUTHS)
    return np.repeat(r, _AZIMUTHS), np.tile(phi, _RADII), weight / weight.sum()


def path_sensitivities(optics, r, phi):
    """(n, 5) path-length change [m] of the rays that reach the aperture at radius r, azimuth
    phi, per unit subreflector motion [dx, dy, dz (m), ax, ay (rad)] of the platform origin
    in {B}: u(P) . (e_in - e_out) with u = d + a x (P - o_P)."""
    f, feed, vertex = optics.points()
    c, a = optics.semi_axes
    theta = 2.0 * np.arctan(r / (2.0 * f))
    e_out = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), -np.cos(theta)], axis=-1)
    P = np.array([0.0, 0.0, f]) + ((c * c - a * a) / (a + c * np.cos(theta)))[:, None] * e_out
    e_in = P - np.array([0.0, 0.0, feed])
    e_in /= np.linalg.norm(e_in, axis=1)[:, None]
    g = e_in - e_out
    arm = P - np.array([0.0, 0.0, vertex - optics.vertex])     # from the platform origin o_P
    tilt_x = arm[:, 1] * g[:, 2] - arm[:, 2] * g[:, 1]          # (x_B cross arm) . g
    tilt_y = arm[:, 2] * g[:, 0] - arm[:, 0] * g[:, 2]          # (y_B cross arm) . g
    return np.column_stack([g, tilt_x, tilt_y])


@lru_cache(maxsize=8)
def sensitivities(optics):
    """(T, Q) for ``optics``: T (2, 5) the beam deviation [rad] in x_B, y_B per unit motion
    (the weighted least-squares tilt of the path-length error over the aperture); Q (5, 5)
    so that d Q d is the mean square path-length error [m^2] left once piston and tilt
    are removed."""
    r, phi, w = _aperture(optics)
    S = path_sensitivities(optics, r, phi)
    basis = np.column_stack([np.ones_like(r), r * np.cos(phi), r * np.sin(phi)])
    root = np.sqrt(w)[:, None]
    fit = np.linalg.lstsq(basis * root, S * root, rcond=None)[0]
    residual = (S - basis @ fit) * root
    T, Q = fit[1:], residual.T @ residual
    T.setflags(write=False)
    Q.setflags(write=False)
    return T, Q


def _poses(name, value):
    array = np.asarray(value, dtype=float)
    if array.ndim not in (1, 2) or array.shape[-1] != 6:
        raise InvalidInputError(f"{name} must be a pose [x, y, z, roll, pitch, yaw] or (n, 6) of them, "
                                f"got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise InvalidInputError(f"{name} must be finite")
    return np.atleast_2d(array)


def subreflector_motion(pose, reference):
    """(n, 5) [dx, dy, dz, ax, ay] of the platform pose(s) against the reference pose(s), both
    [x, y, z, roll, pitch, yaw] in {B}: the origin's offset and the small rotation of
    R R_ref^T as a rotation vector about x_B and y_B (about z_B the subreflector is symmetric)."""
    pose, reference = _poses("pose", pose), _poses("reference", reference)
    r = rpy_matrix(pose[:, 3:]) @ np.swapaxes(rpy_matrix(reference[:, 3:]), 1, 2)
    axis = np.stack([r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]], axis=1)
    sin2 = np.linalg.norm(axis, axis=1)                       # 2 sin(angle)
    angle = np.arctan2(sin2, np.trace(r, axis1=1, axis2=2) - 1.0)
    scale = np.divide(angle, sin2, out=np.full_like(angle, 0.5), where=sin2 > 0)
    return np.column_stack([pose[:, :3] - reference[:, :3], (axis * scale[:, None])[:, :2]])


def _rows(matrix, motion):
    """matrix @ each motion row, summed term by term in a fixed order: a row's result does
    not depend on how many rows come with it (a product's BLAS kernel would)."""
    return sum(motion[:, j, None] * matrix[:, j] for j in range(motion.shape[1]))


def pointing(motion, optics):
    """(n, 2) beam deviation [rad] along x_B and y_B of the subreflector motion(s)
    (``subreflector_motion``)."""
    return _rows(sensitivities(optics)[0], np.atleast_2d(motion))


def path_error(motion, optics):
    """(n,) RMS path-length error over the aperture [m], piston and tilt removed."""
    motion = np.atleast_2d(motion)
    square = np.sum(motion * _rows(sensitivities(optics)[1], motion), axis=1)
    return np.sqrt(np.maximum(square, 0.0))


def ruze(sigma, wavelength):
    """Ruze's efficiency factor exp(-(4 pi sigma / lambda)^2) of a reflector whose surface
    error is sigma [m] RMS at the wavelength [m]."""
    sigma, wavelength = np.asarray(sigma, dtype=float), np.asarray(wavelength, dtype=float)
    if np.any(~np.isfinite(sigma)) or np.any(sigma < 0):
        raise InvalidInputError(f"sigma must be finite and >= 0, got {sigma!r}")
    if np.any(~np.isfinite(wavelength)) or np.any(wavelength <= 0):
        raise InvalidInputError(f"wavelength must be finite and > 0, got {wavelength!r}")
    return np.exp(-(4.0 * np.pi * sigma / wavelength) ** 2)


def efficiency_loss(path_rms, frequency):
    """Fraction of the aperture efficiency lost to a path-length error path_rms [m] at
    frequency [Hz]: 1 - ruze(path_rms / 2, c / frequency) (half the path is the
    equivalent surface error)."""
    return 1.0 - ruze(np.asarray(path_rms, dtype=float) / 2.0, SPEED_OF_LIGHT / np.asarray(frequency, dtype=float))
