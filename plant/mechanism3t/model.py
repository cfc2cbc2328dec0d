"""Decoupled three-translation (3T) parallel mechanism of Shen et al. (2024), "mechanism 1".

Why: the mechanism has a symbolic forward solution (x = x_A2, y = y_A1 + d, z from one
closed form), so position, velocity, acceleration and the virtual-work slider forces are
all closed-form and cheap enough for a real-time co-simulation plant.

Conventions (docs/conventions/mechanism-3t.md; SI inside: m, rad, kg, N)
- Frame O at the static-platform centre, y along the rails of A1 and A3, z up, gravity
  g = 9.8 m/s^2 along -z.  Actuator vector rho = (x_A2, y_A1, y_A3), always in that order.
- A1 = (a, y_A1, 0), A2 = (x_A2, b, 0), A3 = (-a, y_A3, 0), B_i = A_i + (0, 0, l1).
  Limb I swings in the plane y = y_A1 (revolute axes along y), limb II in the plane
  x = x_A2 (axes along x), B3C3 in the plane y = y_A3 (axes along y).
- The platform is the rigid T made of the bar D1D2 (along y, O' at its middle,
  D1 = O' - (0, d, 0), D2 = O' + (0, d, 0)) and the arm E3O' (E3 = O' - (e, 0, 0)).
- Limb III: theta = angle of B3C3 to -x, C3 = (-a - l4 cos theta, y_A3, l1 + l4 sin theta),
  D3 = C3 + (0, 0, l5), D3E3 horizontal of length l6.  theta is kept in [0, pi] (C3 not
  below B3), as the paper's arccos in eq. 11 does.  The forward assembly ``mode`` is the
  sign taken before the square root of eq. 11; it equals sign(W) with
  W = x - e + a + l4 cos theta (E3 on the +x side of D3 for mode = +1).  The paper's
  numerical check is in mode +1.  The inverse (eq. 12) is extended to both signs of
  cos theta (the paper's arcsin keeps only cos theta >= 0), so it has up to 4 branches,
  ordered (cos >= 0, y_A3 = y - root), (cos >= 0, y + root), (cos <= 0, -), (cos <= 0, +).
- The paper's forward solution ignores the passive limbs I and II; here they must close
  too (eq. 8 discriminant >= 0 in their planes, i.e. |l2 - l3| <= |B1D1|, |B2D2| <= l2 + l3),
  so points the paper calls reachable but that those limbs cannot reach raise
  ``UnreachableError``.  Their knees point outward (knee sign -1: the B_iC_i angle is the
  B_iD_i angle minus the triangle angle), the assembly that the paper's Table 1 implies.
- Single loop (paper 1.2): same a, b, d, l1 and l2 = 220, l3 = 160 mm (the spec's fix of
  the swapped lengths in 1.2.3); theta (of B1C1 to +x) is an input, limb II must close.
- Singularities from J_o v = J_i rho_dot with the constraint rows
  f1 = x - x_A2, f2 = y - y_A1 - d, f3 = cos(theta) (W^2 + V^2 - l6^2) / (2 l6),
  V = y - y_A3:  J_o = [[1,0,0],[0,1,0],[W c/l6, V c/l6, -W s/l6]], J_i = diag(1, 1, V c/l6).
  det J_o = -W sin(theta)/l6 gives the paper's output singularities (sin theta = 0 or
  W = 0, section 3.3).  det J_i = V cos(theta)/l6 vanishes where the two eq. 12 branches
  merge (V = 0, D3E3 along x) or theta = pi/2 (z at its maximum): there the platform
  cannot move in z, an input singularity.  The paper's eq. 13 row 3 equals ours divided by
  V cos(theta)/l6, which is why it finds none: its J_o entries diverge there instead.
- Paper typos fixed: eq. 13-15 read J_o v = J_i rho_dot and a = J_o^-1 (J_i rho_ddot - K0);
  f33 has l4, not l4^2, in its numerator (f33 = W tan(theta) / sqrt(l6^2 - W^2)).

Dynamics (paper 4) by the virtual-work principle, F . delta_rho = sum over bodies of
(m (a_c - g) . delta_r_c + I alpha . delta_phi), F = actuator forces on the sliders along
+x (slider 2) and +y (sliders 1 and 3).  Assumptions the paper leaves open:
- Centres of mass at mid-link for B_iC_i, C_iD_i, B3C3, D3E3.  Sliders, C3D3 (R33 along y
  and R34 along z force it to keep its orientation: it only translates), the platform
  (9.2 kg, taken to include the bar D1D2 and the arm E3O') and the 10 kg payload only
  translate, so where their mass sits and their inertias do not matter.
- Table 1 inertias are about the axes of O at the numerical-check configuration, not about
  the centres of mass: with mid-link centres the parallel-axis terms reproduce every entry
  within 6 % (B1C1 and B2C2, identical links, leave the same 19.8e3 kg mm^2 about their
  swing axes), and a 220 mm, 4 kg link cannot have 0.5 kg m^2 about its own centre (at
  most m (L/2)^2 = 0.05 kg m^2).  So each rotating link's own inertia about its swing axis
  (y for limbs I and III, x for limb II, z for D3E3) is the table value minus
  m * (distance of the mid-link point from that axis of O)^2 at that configuration.  For D3E3 this leaves only 335 kg
  mm^2 (a slender rod
  would have 7.3e3) and its Iyy residual is negative, so its centre is likely not
  mid-link; C3D3's residuals are negative too but it only translates.  Products of
  inertia do no work for these fixed-axis rotations.
- Frictionless joints; no external load other than gravity.
"""
from dataclasses import dataclass, replace

import numpy as np

from plant.errors import InvalidInputError, SingularConfigurationError, UnreachablePoseError

MM = 1e-3
KG_MM2 = 1e-6
SINGULAR_TOL = 1e-7  # |det| of the dimensionless J_o (or of a passive 2R limb) below which a solve is refused
X_AXIS, Y_AXIS, Z_AXIS = np.eye(3)

# Paper Table 1 (kg mm^2): (Ixx, Iyy, Izz) about the axes of O at PAPER_REFERENCE_RHO_MM.
PAPER_INERTIA_AT_O = {
    "b1c1": (313099.61, 499432.94, 354762.39),
    "b2c2": (490737.56, 254389.83, 308234.63),
    "b3c3": (158362.42, 503086.49, 360635.38),
    "c1d1": (587493.49, 619956.23, 185990.57),
    "c2d2": (697660.56, 531088.95, 232230.03),
    "c3d3": (294211.32, 609291.81, 326809.24),
    "d3e3": (573901.09, 841323.79, 272191.28),
}
PAPER_REFERENCE_RHO_MM = (94.25, -144.36, -47.68)  # (x_A2, y_A1, y_A3), paper 3.1.3
SWING_AXIS = {"b1c1": 1, "c1d1": 1, "b2c2": 0, "c2d2": 0, "b3c3": 1, "d3e3": 2}


class UnreachableError(UnreachablePoseError):
    """No real assembly: a square root (eq. 7, 8, 10-12) or arccos/arcsin argument is out of range.

    Bad shapes, NaN and inf raise plant.errors.InvalidInputError; solves at singular
    configurations raise plant.errors.SingularConfigurationError."""


@dataclass(frozen=True)
class Mechanism3TParams:
    """Dimensions (m), masses (kg), own inertias about the swing axes through the centres (kg m^2),
    knee signs of the passive limbs I and II (-1: B_iC_i turned clockwise from B_iD_i in the
    (x or y, z) plane, i.e. knee outward), gravity (m/s^2) and actuator ranges (m)."""
    a: float
    b: float
    d: float
    e: float
    l1: float
    l2: float
    l3: float
    l4: float
    l5: float
    l6: float
    m_slider: float
    m_b1c1: float
    m_c1d1: float
    m_b2c2: float
    m_c2d2: float
    m_b3c3: float
    m_c3d3: float
    m_d3e3: float
    m_platform: float
    m_payload: float
    i_b1c1: float = 0.0
    i_c1d1: float = 0.0
    i_b2c2: float = 0.0
    i_c2d2: float = 0.0
    i_b3c3: float = 0.0
    i_d3e3: float = 0.0
    knee_1: int = -1
    knee_2: int = -1
    g: float = 9.8
    rho_min: tuple = (-0.5, -1.0, -0.5)  # actuator ranges of paper 3.4, same order as rho
    rho_max: tuple = (0.6, 1.0, 0.5)

    @classmethod
    def paper(cls):
        """Paper 3.1.3 dimensions and section 4.3 masses, 10 kg payload, Table 1 inertias."""
        mm = {k: v * MM for k, v in dict(a=280, b=220, d=152, e=300, l1=120, l2=220, l3=160,
                                         l4=180, l5=125, l6=160).items()}
        base = cls(**mm, m_slider=4.53, m_b1c1=4.04, m_c1d1=3.67, m_b2c2=4.04, m_c2d2=3.67,
                   m_b3c3=3.47, m_c3d3=2.53, m_d3e3=3.43, m_platform=9.2, m_payload=10.0)
        rho = np.array(PAPER_REFERENCE_RHO_MM) * MM
        centres = {name: body[2][0] for name, body in _bodies(base, rho, np.zeros(3), np.zeros(3), 1).items()}
        own = {}
        for name, axis in SWING_AXIS.items():
            r = centres[name]
            at_o = PAPER_INERTIA_AT_O[name][axis] * KG_MM2
            own["i_" + name] = float(at_o - getattr(base, "m_" + name) * (r @ r - r[axis] ** 2))
        return replace(base, **own)


def _finite(name, value, point=False):
    """value as a finite float array of shape (..., 3), (3,) if point, () if point is None."""
    arr = np.asarray(value, dtype=float)
    expected = {None: (), True: (3,), False: (3,)}[point]
    if (arr.shape[-1:] if point is False else arr.shape) != expected:
        raise InvalidInputError(f"{name} has shape {arr.shape}, expected {'(..., 3)' if point is False else expected}")
    if not np.all(np.isfinite(arr)):
        raise InvalidInputError(f"{name} contains NaN or inf")
    return arr


def _inputs(rho, rho_dot, rho_ddot):
    return np.broadcast_arrays(*(_finite(n, v) for n, v in (("rho", rho), ("rho_dot", rho_dot), ("rho_ddot",
                                                                                                 rho_ddot))))


def _eq8_disc(u, w, l_in, l_out):
    """Eq. 8 discriminant N1^2 + N2^2 - N3^2 of a planar 2R limb reaching (u, w) from its base."""
    n1, n2 = -2 * l_in * w, -2 * l_in * u
    n3 = l_out ** 2 - l_in ** 2 - u ** 2 - w ** 2
    return n1 ** 2 + n2 ** 2 - n3 ** 2


def _passive_violations(P, p):
    """Closure conditions of the passive limbs I (plane y = y_A1) and II (plane x = x_A2)."""
    x, y, z = np.moveaxis(p, -1, 0)
    return [(_eq8_disc(x - P.a, z - P.l1, P.l2, P.l3) < 0,
             "limb I cannot close: eq. 8 square root negative (|B1D1| outside [|l2 - l3|, l2 + l3])"),
            (_eq8_disc(y + P.d - P.b, z - P.l1, P.l2, P.l3) < 0,
             "limb II cannot close: eq. 8 square root negative (|B2D2| outside [|l2 - l3|, l2 + l3])")]


def _raise_first(violations, error=UnreachableError):
    for bad, message in violations:
        if np.any(bad):
            raise error(message)


# ---------------------------------------------------------------- single loop (paper 1.2)

def single_loop_forward(P, x_A2, y_A1, theta):
    """Eq. 7: every real O' (k, 3) of the single-loop mechanism, '+' root first."""
    x_A2, y_A1, theta = (float(_finite(n, v, None)) for n, v in (("x_A2", x_A2), ("y_A1", y_A1), ("theta", theta)))
    root2 = P.l3 ** 2 - (x_A2 - P.a - P.l2 * np.cos(theta)) ** 2
    if root2 < 0:
        raise UnreachableError("eq. 7: l3^2 - (x_A2 - a - l2 cos theta)^2 < 0")
    z = P.l1 + P.l2 * np.sin(theta) + np.array([1.0, -1.0]) * np.sqrt(root2)
    p = np.stack([np.full(2, x_A2), np.full(2, y_A1 + P.d), z], axis=-1)
    bad_limb2 = _passive_violations(P, p)[1]
    if np.all(bad_limb2[0]):
        raise UnreachableError(bad_limb2[1])
    return p[~bad_limb2[0]]


def single_loop_inverse(P, p):
    """Eq. 8: every real (x_A2, y_A1, theta) (k, 3), theta wrapped to (-pi, pi], '+' root first."""
    x, y, z = _finite("p", p, True)
    n1, n2 = -2 * P.l2 * (z - P.l1), -2 * P.l2 * (x - P.a)
    n3 = P.l3 ** 2 - P.l2 ** 2 - (x - P.a) ** 2 - (z - P.l1) ** 2
    disc = n1 ** 2 + n2 ** 2 - n3 ** 2
    if disc < 0:
        raise UnreachableError("eq. 8: N1^2 + N2^2 - N3^2 < 0 (limb I cannot reach O')")
    _raise_first(_passive_violations(P, np.array([x, y, z]))[1:])
    theta = 2 * np.arctan2(n1 + np.array([1.0, -1.0]) * np.sqrt(disc), n2 + n3)
    theta = np.angle(np.exp(1j * theta))
    return np.stack([np.full(2, x), np.full(2, y - P.d), theta], axis=-1)


# ---------------------------------------------------------------- mechanism 1 positions (paper 3.1)

def _forward(P, rho, mode):
    """theta and O' of branch `mode` (batched) plus the list of violated conditions."""
    x_A2, y_A1, y_A3 = np.moveaxis(rho, -1, 0)
    root2 = P.l6 ** 2 - (y_A1 + P.d - y_A3) ** 2
    cos = (P.e - P.a - x_A2 + mode * np.sqrt(np.clip(root2, 0, None))) / P.l4
    theta = np.arccos(np.clip(cos, -1, 1))
    p = np.stack([x_A2, y_A1 + P.d, P.l1 + P.l5 + P.l4 * np.sin(theta)], axis=-1)
    sign = "+" if mode > 0 else "-"
    violations = [(root2 < 0, "eq. 10-11: l6^2 - (y_A1 + d - y_A3)^2 < 0 (D3E3 too short for the y offset)"),
                  (np.abs(cos) > 1, f"eq. 11: arccos argument (N3 {sign} sqrt(l6^2 - N4^2))/l4 outside [-1, 1]")]
    return theta, p, violations + _passive_violations(P, p)


def _check_mode(mode):
    if mode not in (1, -1):
        raise InvalidInputError(f"mode must be +1 or -1 (sign before the eq. 11 square root), got {mode!r}")


def forward_branch(P, rho, mode=1):
    """O' (..., 3) of assembly mode `mode` for batched rho (..., 3); raises if any sample has none."""
    _check_mode(mode)
    _, p, violations = _forward(P, _finite("rho", rho), mode)
    _raise_first(violations)
    return p


def forward_position(P, rho):
    """Every real O' (k, 3), k = 1 or 2, for one rho = (x_A2, y_A1, y_A3); mode +1 first if real."""
    rho = _finite("rho", rho, True)
    found, reasons = [], []
    for mode in (1, -1):
        _, p, violations = _forward(P, rho, mode)
        failed = [message for bad, message in violations if bad]
        if failed:
            reasons.append(f"mode {mode:+d}: {failed[0]}")
        else:
            found.append(p)
    if not found:
        raise UnreachableError("; ".join(reasons))
    return np.array(found)


def assembled(P, rho, mode):
    """(mask (...), reason): which rho (..., 3) have an O' in assembly mode ``mode``, and the
    first condition that fails ('' if none); no raise: the checks of a scenario tell the
    reason with the setting that caused it."""
    _, _, violations = _forward(P, _finite("rho", rho), mode)
    bad = np.any([b for b, _ in violations], axis=0)
    return ~bad, next((message for b, message in violations if np.any(b)), "")


def reach(P, centre, mode, direction=(1.0, 1.0, 1.0), limit=1.0, step=1e-4):
    """(low, high) [m]: the offsets d along ``direction`` (the paper 4.3 motion moves every
    slider alike) for which centre + d' direction assembles in mode ``mode`` for every d'
    between 0 and d, found on a grid of ``step`` out to ``limit``; None if centre does not."""
    d = np.arange(0.0, limit + step / 2, step)
    ends = []
    for sign in (-1.0, 1.0):
        ok = assembled(P, _finite("centre", centre, True) + sign * d[:, None] * np.asarray(direction), mode)[0]
        first = int(np.argmin(ok)) if not ok.all() else len(d)
        if first == 0:
            return None
        ends.append(sign * d[first - 1])
    return ends[0], ends[1]


def assembly_mode(P, rho, p_near):
    """The mode (+1/-1) whose O' is nearest p_near."""
    rho = _finite("rho", rho, True)
    modes = [m for m in (1, -1) if not any(np.any(b) for b, _ in _forward(P, rho, m)[2])]
    if not modes:
        forward_position(P, rho)  # raises with the reasons
    p_near = _finite("p_near", p_near, True)
    return min(modes, key=lambda m: np.linalg.norm(_forward(P, rho, m)[1] - p_near))


def _inverse_all(P, p):
    """All 4 eq. 12 branches (..., 4, 3) and their validity (..., 4), ignoring the passive limbs."""
    x, y, z = np.moveaxis(p, -1, 0)
    sin = (z - P.l1 - P.l5) / P.l4
    cos = np.sqrt(np.clip(1 - sin ** 2, 0, None))[..., None] * np.array([1.0, 1.0, -1.0, -1.0])
    w = (x - P.e + P.a)[..., None] + P.l4 * cos
    root2 = P.l6 ** 2 - w ** 2
    y_A3 = y[..., None] + np.array([-1.0, 1.0, -1.0, 1.0]) * np.sqrt(np.clip(root2, 0, None))
    rho = np.stack(np.broadcast_arrays(x[..., None], (y - P.d)[..., None], y_A3), axis=-1)
    ok = (root2 >= 0) & ((sin >= 0) & (sin <= 1))[..., None]
    return rho, ok


def inverse_position(P, p):
    """Every real rho = (x_A2, y_A1, y_A3) (k, 3), k <= 4, reaching O' = p (eq. 12 branches)."""
    p = _finite("p", p, True)
    sin = (p[2] - P.l1 - P.l5) / P.l4
    if not 0 <= sin <= 1:
        raise UnreachableError(
            f"eq. 12: arcsin argument (z - l1 - l5)/l4 = {sin:.6g} outside [0, 1] (theta in [0, pi])"
        )
    rho, ok = _inverse_all(P, p)
    if not ok.any():
        raise UnreachableError("eq. 12: l6^2 - (x - e + a + l4 cos theta)^2 < 0 for both signs of cos theta")
    _raise_first(_passive_violations(P, p))
    return rho[ok]


# ---------------------------------------------------------------- velocity, acceleration (paper 3.2)

def _limb3_motion(P, rho, rho_dot, rho_ddot, mode):
    """(theta, W, V, O') each as (value, rate, acceleration), by differentiating W^2 + V^2 = l6^2."""
    _check_mode(mode)
    rho, rho_dot, rho_ddot = _inputs(rho, rho_dot, rho_ddot)
    theta, p, violations = _forward(P, rho, mode)
    _raise_first(violations)
    x_d, y1_d, y3_d = np.moveaxis(rho_dot, -1, 0)
    x_dd, y1_dd, y3_dd = np.moveaxis(rho_ddot, -1, 0)
    sin, cos = np.sin(theta), np.cos(theta)
    w = p[..., 0] - P.e + P.a + P.l4 * cos
    v = p[..., 1] - rho[..., 2]
    _raise_first([(np.abs(sin) < SINGULAR_TOL,
                   "output singularity (paper 3.3, f33 = 0): sin theta = 0, D3C3 perpendicular to B3C3"),
                  (np.abs(w) / P.l6 < SINGULAR_TOL,
                   "output singularity (paper 3.3, f33 = 0): x - e + a + l4 cos theta = 0, E3 and C3 share x")],
                 SingularConfigurationError)
    v_d, v_dd = y1_d - y3_d, y1_dd - y3_dd
    den = w * P.l4 * sin
    th_d = (w * x_d + v * v_d) / den
    w_d = x_d - P.l4 * sin * th_d
    th_dd = (w_d ** 2 + v_d ** 2 + v * v_dd + w * (x_dd - P.l4 * cos * th_d ** 2)) / den
    w_dd = x_dd - P.l4 * cos * th_d ** 2 - P.l4 * sin * th_dd
    o_vel = np.stack([x_d, y1_d, P.l4 * cos * th_d], axis=-1)
    o_acc = np.stack([x_dd, y1_dd, P.l4 * (cos * th_dd - sin * th_d ** 2)], axis=-1)
    return (theta, th_d, th_dd), (w, w_d, w_dd), (v, v_d, v_dd), (p, o_vel, o_acc)


def velocity(P, rho, rho_dot, mode=1):
    """Velocity of O' (..., 3) for batched rho, rho_dot (eq. 14, v = J_o^-1 J_i rho_dot)."""
    return _limb3_motion(P, rho, rho_dot, np.zeros(3), mode)[3][1]


def acceleration(P, rho, rho_dot, rho_ddot, mode=1):
    """Acceleration of O' (..., 3) (eq. 15, J_o^-1 (J_i rho_ddot - K0)); with rho_ddot = 0 it is the
    velocity-product term -J_o^-1 K0."""
    return _limb3_motion(P, rho, rho_dot, rho_ddot, mode)[3][2]


def jacobians(P, rho, mode=1):
    """(J_o, J_i), each (..., 3, 3), dimensionless, with J_o v = J_i rho_dot (see module docstring)."""
    _check_mode(mode)
    rho = _finite("rho", rho)
    theta, p, violations = _forward(P, rho, mode)
    _raise_first(violations)
    c, s = np.cos(theta), np.sin(theta)
    w = (p[..., 0] - P.e + P.a + P.l4 * c) / P.l6
    v = (p[..., 1] - rho[..., 2]) / P.l6
    zero, one = np.zeros_like(c), np.ones_like(c)
    j_o = np.stack([np.stack([one, zero, zero], -1), np.stack([zero, one, zero], -1),
                    np.stack([w * c, v * c, -w * s], -1)], -2)
    j_i = np.stack([np.stack([one, zero, zero], -1), np.stack([zero, one, zero], -1),
                    np.stack([zero, zero, v * c], -1)], -2)
    return j_o, j_i


# ---------------------------------------------------------------- singularities (paper 3.3)

@dataclass(frozen=True)
class SingularityReport:
    kind: str              # "regular", "input", "output" or "combined"
    det_jo: float          # -W sin(theta)/l6; zero on output singularities (paper's f33 = 0)
    det_ji: float          # V cos(theta)/l6; zero on input singularities
    sigma_min_jo: float    # smallest singular value of J_o
    theta_margin: float    # rad, distance in theta (x fixed) to sin theta = 0 or W = 0


def singularity(P, rho, mode=1, tol=SINGULAR_TOL):
    """Classify one configuration and measure its distance to the nearest output singularity."""
    rho = _finite("rho", rho, True)
    j_o, j_i = jacobians(P, rho, mode)
    det_o, det_i = float(np.linalg.det(j_o)), float(np.linalg.det(j_i))
    theta = _forward(P, rho, mode)[0]
    at_w0 = (P.e - P.a - rho[0]) / P.l4  # cos theta where W = 0
    candidates = [0.0, np.pi] + ([float(np.arccos(at_w0))] if abs(at_w0) <= 1 else [])
    kind = {(False, False): "regular", (True, False): "input", (False, True): "output",
            (True, True): "combined"}[(abs(det_i) < tol, abs(det_o) < tol)]
    return SingularityReport(kind, det_o, det_i, float(np.linalg.svd(j_o, compute_uv=False)[-1]),
                             float(min(abs(theta - c) for c in candidates)))


# ---------------------------------------------------------------- workspace (paper 3.4)

@dataclass(frozen=True)
class Workspace:
    points: np.ndarray     # (n, 3) reachable O' on a cell-centred grid, m
    volume: float          # m^3 (cells x step^3)
    step: float            # grid step, m
    passive_limbs: bool    # False: the paper's criterion (eq. 11 only)


def workspace(P, step=0.01, passive_limbs=True):
    """Reachable O' for the actuator ranges P.rho_min..P.rho_max.

    x = x_A2 and y = y_A1 + d run over the slider ranges on a grid, z over
    [l1 + l5, l1 + l5 + l4]; a point is kept if some eq. 12 branch has y_A3 in range
    (and, with passive_limbs, limbs I and II close)."""
    lo, hi = np.array(P.rho_min, float), np.array(P.rho_max, float)
    axes = [np.arange(a0 + step / 2, a1, step) for a0, a1 in
            ((lo[0], hi[0]), (lo[1] + P.d, hi[1] + P.d), (P.l1 + P.l5, P.l1 + P.l5 + P.l4))]
    xx, yy = np.meshgrid(axes[0], axes[1], indexing="ij")
    found = []
    for z in axes[2]:
        p = np.stack([xx, yy, np.full_like(xx, z)], axis=-1).reshape(-1, 3)
        rho, ok = _inverse_all(P, p)
        inside = np.any(ok & (rho[..., 2] >= lo[2]) & (rho[..., 2] <= hi[2]), axis=-1)
        if passive_limbs:
            inside &= ~np.any([bad for bad, _ in _passive_violations(P, p)], axis=0)
        found.append(p[inside])
    points = np.concatenate(found)
    return Workspace(points, len(points) * step ** 3, step, passive_limbs)


# ---------------------------------------------------------------- dynamics (paper 4)

def _two_link(target, l_in, l_out, knee, name):
    """Angles of B->C and C->D of a planar 2R limb reaching target = (u, w) jets, with rates and accelerations."""
    (u, u_d, u_dd), (w, w_d, w_dd) = target
    r = np.hypot(u, w)
    alpha = np.arctan2(w, u) + knee * np.arccos(np.clip((l_in ** 2 + r ** 2 - l_out ** 2) / (2 * l_in * r), -1, 1))
    beta = np.arctan2(w - l_in * np.sin(alpha), u - l_in * np.cos(alpha))
    s = np.sin(beta - alpha)
    _raise_first([(np.abs(s) < SINGULAR_TOL, f"{name} fully stretched or folded (|BD| = l2 +- l3)")],
                 SingularConfigurationError)
    ca, sa, cb, sb = np.cos(alpha), np.sin(alpha), np.cos(beta), np.sin(beta)
    a_d = (u_d * cb + w_d * sb) / (l_in * s)
    b_d = -(u_d * ca + w_d * sa) / (l_out * s)
    q_u = u_dd + l_in * a_d ** 2 * ca + l_out * b_d ** 2 * cb
    q_w = w_dd + l_in * a_d ** 2 * sa + l_out * b_d ** 2 * sb
    return (alpha, a_d, (q_u * cb + q_w * sb) / (l_in * s)), (beta, b_d, -(q_u * ca + q_w * sa) / (l_out * s))


def _along(base, angle, length, u_axis, w_axis):
    """base + length (cos angle u_axis + sin angle w_axis) with its first two time derivatives."""
    (b, b_d, b_dd), (q, q_d, q_dd) = base, (x[..., None] for x in angle)
    e = np.cos(q) * u_axis + np.sin(q) * w_axis
    n = -np.sin(q) * u_axis + np.cos(q) * w_axis
    return b + length * e, b_d + length * q_d * n, b_dd + length * (q_dd * n - q_d ** 2 * e)


def _bodies(P, rho, rho_dot, rho_ddot, mode):
    """name -> (mass, own inertia about swing axis, centre (pos, vel, acc), swing angle jet or None)."""
    rho, rho_dot, rho_ddot = _inputs(rho, rho_dot, rho_ddot)
    theta, (w, w_d, w_dd), (v, v_d, v_dd), o = _limb3_motion(P, rho, rho_dot, rho_ddot, mode)
    x, y, z = (tuple(j[..., i] for j in o) for i in range(3))
    psi = (np.arctan2(v, w), (w * v_d - v * w_d) / P.l6 ** 2, (w * v_dd - v * w_dd) / P.l6 ** 2)
    th1, be1 = _two_link(((x[0] - P.a, x[1], x[2]), (z[0] - P.l1, z[1], z[2])), P.l2, P.l3, P.knee_1, "limb I")
    th2, be2 = _two_link(((y[0] + P.d - P.b, y[1], y[2]), (z[0] - P.l1, z[1], z[2])), P.l2, P.l3, P.knee_2, "limb II")

    def slider(position, axis, index):
        return (position, rho_dot[..., index, None] * axis, rho_ddot[..., index, None] * axis)

    zeros = np.zeros_like(rho[..., 0])
    s1 = slider(np.stack([zeros + P.a, rho[..., 1], zeros], -1), Y_AXIS, 1)
    s2 = slider(np.stack([rho[..., 0], zeros + P.b, zeros], -1), X_AXIS, 0)
    s3 = slider(np.stack([zeros - P.a, rho[..., 2], zeros], -1), Y_AXIS, 2)
    b1, b2, b3 = ((j[0] + P.l1 * Z_AXIS, j[1], j[2]) for j in (s1, s2, s3))
    c1, c2 = _along(b1, th1, P.l2, X_AXIS, Z_AXIS), _along(b2, th2, P.l2, Y_AXIS, Z_AXIS)
    c3 = _along(b3, theta, P.l4, -X_AXIS, Z_AXIS)
    d3 = (c3[0] + P.l5 * Z_AXIS, c3[1], c3[2])
    return {
        "slider_2": (P.m_slider, 0.0, s2, None),
        "slider_1": (P.m_slider, 0.0, s1, None),
        "slider_3": (P.m_slider, 0.0, s3, None),
        "b1c1": (P.m_b1c1, P.i_b1c1, _along(b1, th1, P.l2 / 2, X_AXIS, Z_AXIS), th1),
        "c1d1": (P.m_c1d1, P.i_c1d1, _along(c1, be1, P.l3 / 2, X_AXIS, Z_AXIS), be1),
        "b2c2": (P.m_b2c2, P.i_b2c2, _along(b2, th2, P.l2 / 2, Y_AXIS, Z_AXIS), th2),
        "c2d2": (P.m_c2d2, P.i_c2d2, _along(c2, be2, P.l3 / 2, Y_AXIS, Z_AXIS), be2),
        "b3c3": (P.m_b3c3, P.i_b3c3, _along(b3, theta, P.l4 / 2, -X_AXIS, Z_AXIS), theta),
        "c3d3": (P.m_c3d3, 0.0, (c3[0] + P.l5 / 2 * Z_AXIS, c3[1], c3[2]), None),
        "d3e3": (P.m_d3e3, P.i_d3e3, _along(d3, psi, P.l6 / 2, X_AXIS, Y_AXIS), psi),
        "platform": (P.m_platform + P.m_payload, 0.0, o, None),
    }


def energy(P, rho, rho_dot, mode=1):
    """(kinetic, potential) energy in J, batched; potential is zero at z = 0."""
    kinetic = potential = 0.0
    for m, inertia, (r, r_d, _), angle in _bodies(P, rho, rho_dot, np.zeros(3), mode).values():
        kinetic = kinetic + 0.5 * m * np.sum(r_d ** 2,
                                             axis=-1) + (0.0 if angle is None else 0.5 * inertia * angle[1] ** 2)
        potential = potential + m * P.g * r[..., 2]
    return kinetic, potential


def slider_forces(P, rho, rho_dot, rho_ddot, mode=1):
    """Actuator forces (..., 3) in N on the sliders (x_A2, y_A1, y_A3) along +x, +y, +y (virtual work)."""
    rho, rho_dot, rho_ddot = _inputs(rho, rho_dot, rho_ddot)
    moving = _bodies(P, rho, rho_dot, rho_ddot, mode)
    unit = np.broadcast_to(np.eye(3), rho.shape[:-1] + (3, 3))  # rho_dot = e_i gives the velocity Jacobians
    virtual = _bodies(P, rho[..., None, :], unit, np.zeros(3), mode)
    force = 0.0
    for name, (m, inertia, (_, _, acc), angle) in moving.items():
        _, _, (_, jac, _), jac_angle = virtual[name]
        force = force + m * np.sum((acc + P.g * Z_AXIS)[..., None, :] * jac, axis=-1)
        if angle is not None:
            force = force + inertia * angle[2][..., None] * jac_angle[1]
    return force


@dataclass(frozen=True)
class SliderForceHistory:
    t: np.ndarray          # (n,) s
    rho: np.ndarray        # (n, 3) m
    forces: np.ndarray     # (n, 3) N, order (x_A2, y_A1, y_A3)
    peak: float            # max |force| over sliders and time, N
    peak_slider: str       # which actuator


def paper_example(P=None, t=None, amplitude=0.010, omega=0.5):
    """Paper 4.3: every slider moves amplitude*sin(omega t) about the numerical-check configuration."""
    P = Mechanism3TParams.paper() if P is None else P
    t = np.linspace(0.0, 4 * np.pi / omega, 401) if t is None else np.asarray(t, float)
    s = np.sin(omega * t)[:, None] * np.ones(3)
    rho = np.array(PAPER_REFERENCE_RHO_MM) * MM + amplitude * s
    rho_dot = amplitude * omega * np.cos(omega * t)[:, None] * np.ones(3)
    forces = slider_forces(P, rho, rho_dot, -amplitude * omega ** 2 * s, mode=1)
    i, j = np.unravel_index(np.argmax(np.abs(forces)), forces.shape)
    return SliderForceHistory(t, rho, forces, float(abs(forces[i, j])), ("x_A2", "y_A1", "y_A3")[j])


# ---------------------------------------------------------------- forward dynamics (slider coordinates)

def dynamics_terms(P, rho, rho_dot, mode=1):
    """(M, bias) with slider_forces(P, rho, rho_dot, rho_ddot) = M rho_ddot + bias.

    M (..., 3, 3) [kg] is the generalised mass matrix in slider coordinates (symmetric,
    positive definite away from singularities), bias (..., 3) [N] the velocity-product and
    gravity forces.  Both come from the virtual-work sums of slider_forces, over one
    evaluation of the bodies: row 0 moves with rho_dot and zero slider accelerations (its
    accelerations are the velocity-product terms), rows 1-3 with unit slider rates (their
    velocities are the velocity Jacobians of every centre of mass and swing angle)."""
    rho = _finite("rho", rho)
    rho_dot = _finite("rho_dot", rho_dot)
    shape = np.broadcast_shapes(rho.shape, rho_dot.shape)
    rates = np.concatenate([np.broadcast_to(rho_dot, shape)[..., None, :],
                            np.broadcast_to(np.eye(3), shape[:-1] + (3, 3))], axis=-2)
    bodies = _bodies(P, np.broadcast_to(rho, shape)[..., None, :], rates, np.zeros(3), mode).values()
    m = np.array([b[0] for b in bodies])
    vel = np.stack([b[2][1] for b in bodies])                       # (bodies, ..., 4, 3)
    acc = np.stack([b[2][2][..., 0, :] for b in bodies]) + P.g * Z_AXIS
    turning = [b for b in bodies if b[3] is not None]
    inertia = np.array([b[1] for b in turning])
    angle_rate = np.stack([b[3][1] for b in turning])               # (turning, ..., 4)
    angle_acc = np.stack([b[3][2][..., 0] for b in turning])
    jac, jac_angle = vel[..., 1:, :], angle_rate[..., 1:]          # velocity Jacobians per slider
    mass = (np.einsum("b,b...ik,b...jk->...ij", m, jac, jac)
            + np.einsum("b,b...i,b...j->...ij", inertia, jac_angle, jac_angle))
    bias = (np.einsum("b,b...k,b...ik->...i", m, acc, jac)
            + np.einsum("b,b...,b...i->...i", inertia, angle_acc, jac_angle))
    return mass, bias


def mass_matrix(P, rho, mode=1):
    """Generalised mass matrix (..., 3, 3) [kg] in slider coordinates (x_A2, y_A1, y_A3)."""
    return dynamics_terms(P, rho, np.zeros(3), mode)[0]


def forward_dynamics(P, rho, rho_dot, forces, mode=1):
    """Slider accelerations (..., 3) [m/s^2] under slider forces (..., 3) [N]: the inverse of
    slider_forces, rho_ddot = M^-1 (forces - bias).  Raises InvalidInputError on NaN/inf,
    UnreachableError / SingularConfigurationError where slider_forces would."""
    forces = _finite("slider forces", forces)
    mass, bias = dynamics_terms(P, rho, rho_dot, mode)
    rhs = np.broadcast_to(forces - bias, np.broadcast_shapes(forces.shape, bias.shape))
    return np.linalg.solve(mass, rhs[..., None])[..., 0]


def paper_motion(t, centre=None, amplitude=0.010, omega=0.5):
    """Slider motion of paper 4.3 at time(s) t: rho = centre + amplitude sin(omega t) on every
    slider, with its rate and acceleration, each shaped t.shape + (3,). centre defaults to
    the numerical-check configuration (m); amplitude in m, omega in rad/s."""
    centre = np.array(PAPER_REFERENCE_RHO_MM) * MM if centre is None else _finite("centre", centre, True)
    t = np.asarray(t, dtype=float)[..., None] * np.ones(3)
    s, c = np.sin(omega * t), np.cos(omega * t)
    return centre + amplitude * s, amplitude * omega * c, -amplitude * omega ** 2 * s
