"""Compiled single-state kernel of the 3T mechanism (plant.mechanism3t): O', the generalised
mass matrix M, the bias forces and the forward dynamics for ONE state, and an RHS for the
plant FMU.

Why compiled: plant.mechanism3t evaluates the bodies with numpy on tiny arrays, ~420 µs of
fixed per-call costs for a single state; the plant FMU calls forward dynamics four times per
RK4 substep and the slider controller the inverse dynamics once per step. Here one state is
a few µs of scalar code: 3-tuples/scalars, no allocation except the returned arrays. The
validated, batched numpy API in plant.mechanism3t stays the reference (tests hold the two
equal to ~1e-12 relative); this module repeats its formulas (_forward, _limb3_motion,
_two_link, _along, _bodies, dynamics_terms) term by term, with rho_ddot = 0 for the bias
and unit slider rates for the velocity Jacobians, as dynamics_terms does.

The kernels never raise: they return a status code (OK or one of the codes below), and
the Python wrappers raise the reference's errors with the reference's messages
(InvalidInputError for NaN/inf, UnreachableError, SingularConfigurationError), never NaN.
The compiled code is cached on disk beside this file (numba cache=True).
"""
import functools
import math

import numpy as np
from numba import njit

from .errors import InvalidInputError, SingularConfigurationError
from .linalg import solve
from .mechanism3t import SINGULAR_TOL, Mechanism1Params, UnreachableError, _check_mode

OK = 0
BAD_RHO, BAD_RHO_DOT, BAD_FORCE, BAD_RHO_DDOT = 1, 2, 3, 4
UNREACH_D3E3, UNREACH_ARCCOS, UNREACH_LIMB1, UNREACH_LIMB2 = 10, 11, 12, 13
SING_SIN, SING_W, SING_LIMB1, SING_LIMB2, SING_MASS = 20, 21, 22, 23, 24

# Body order of the packed masses (that of plant.mechanism3t._bodies) and of the turning ones.
BODIES = ("slider_2", "slider_1", "slider_3", "b1c1", "c1d1", "b2c2", "c2d2", "b3c3", "c3d3", "d3e3", "platform")
TURNING = ("b1c1", "c1d1", "b2c2", "c2d2", "b3c3", "d3e3")
_NB = len(BODIES)
_ZERO_GEO = (0.0,) * 21
_M0, _I0 = 13, 13 + len(BODIES)   # offsets of masses and inertias in the packed parameters


@functools.lru_cache(maxsize=16)
def pack(P):
    """Mechanism1Params as the float64 array the kernels read."""
    head = [P.a, P.b, P.d, P.e, P.l1, P.l2, P.l3, P.l4, P.l5, P.l6, P.g, float(P.knee_1), float(P.knee_2)]
    masses = [P.m_slider] * 3 + [getattr(P, "m_" + n) for n in BODIES[3:-1]] + [P.m_platform + P.m_payload]
    inertias = [getattr(P, "i_" + n) for n in TURNING]
    packed = np.array(head + masses + inertias, dtype=float)
    packed.flags.writeable = False
    return packed


def _packed(P):
    return pack(P) if isinstance(P, Mechanism1Params) else P


# ---------------------------------------------------------------- compiled kernels

@njit(cache=True)
def _eq8_disc(u, w, l_in, l_out):
    n1, n2 = -2 * l_in * w, -2 * l_in * u
    n3 = l_out ** 2 - l_in ** 2 - u ** 2 - w ** 2
    return n1 ** 2 + n2 ** 2 - n3 ** 2


@njit(cache=True)
def _position(pa, x_A2, y_A1, y_A3, mode):
    """(status, theta, z) of O' = (x_A2, y_A1 + d, z) in assembly mode `mode` (_forward)."""
    a, b, d, e, l1, l2, l3, l4, l5, l6 = pa[0], pa[1], pa[2], pa[3], pa[4], pa[5], pa[6], pa[7], pa[8], pa[9]
    root2 = l6 ** 2 - (y_A1 + d - y_A3) ** 2
    cos = (e - a - x_A2 + mode * math.sqrt(max(root2, 0.0))) / l4
    theta = math.acos(min(max(cos, -1.0), 1.0))
    z = l1 + l5 + l4 * math.sin(theta)
    if root2 < 0:
        return UNREACH_D3E3, theta, z
    if abs(cos) > 1:
        return UNREACH_ARCCOS, theta, z
    if _eq8_disc(x_A2 - a, z - l1, l2, l3) < 0:
        return UNREACH_LIMB1, theta, z
    if _eq8_disc(y_A1 + d + d - b, z - l1, l2, l3) < 0:
        return UNREACH_LIMB2, theta, z
    return OK, theta, z


@njit(cache=True)
def _knee(u, w, l_in, l_out, knee):
    """(alpha, beta, sin(beta - alpha)) of a planar 2R limb reaching (u, w) (_two_link)."""
    r = math.hypot(u, w)
    c = (l_in ** 2 + r ** 2 - l_out ** 2) / (2 * l_in * r)
    alpha = math.atan2(w, u) + knee * math.acos(min(max(c, -1.0), 1.0))
    beta = math.atan2(w - l_in * math.sin(alpha), u - l_in * math.cos(alpha))
    return alpha, beta, math.sin(beta - alpha)


@njit(cache=True)
def _knee_rates(u_d, u_dd, w_d, w_dd, ca, sa, cb, sb, s, l_in, l_out):
    """(alpha_d, alpha_dd, beta_d, beta_dd) of _two_link."""
    a_d = (u_d * cb + w_d * sb) / (l_in * s)
    b_d = -(u_d * ca + w_d * sa) / (l_out * s)
    q_u = u_dd + l_in * a_d ** 2 * ca + l_out * b_d ** 2 * cb
    q_w = w_dd + l_in * a_d ** 2 * sa + l_out * b_d ** 2 * sb
    return a_d, (q_u * cb + q_w * sb) / (l_in * s), b_d, -(q_u * ca + q_w * sa) / (l_out * s)


@njit(cache=True)
def _arm(q_d, q_dd, cq, sq, length):
    """In-plane (u, w) velocity and acceleration of length * (cos q, sin q) (_along)."""
    return (-length * q_d * sq, length * q_d * cq,
            length * (-q_dd * sq - q_d ** 2 * cq), length * (q_dd * cq - q_d ** 2 * sq))


@njit(cache=True)
def _geometry(pa, rho, mode):
    """(status, O' z, rate-independent quantities) of one configuration."""
    a, b, d, e, l1, l2, l3, l4, l6 = pa[0], pa[1], pa[2], pa[3], pa[4], pa[5], pa[6], pa[7], pa[9]
    x, y = rho[0], rho[1] + d
    status, theta, z = _position(pa, rho[0], rho[1], rho[2], mode)
    geo = _ZERO_GEO
    if status != OK:
        return status, z, geo
    sin, cos = math.sin(theta), math.cos(theta)
    w = x - e + a + l4 * cos
    v = y - rho[2]
    if abs(sin) < SINGULAR_TOL:
        return SING_SIN, z, geo
    if abs(w) / l6 < SINGULAR_TOL:
        return SING_W, z, geo
    al1, be1, s1 = _knee(x - a, z - l1, l2, l3, pa[11])
    if abs(s1) < SINGULAR_TOL:
        return SING_LIMB1, z, geo
    al2, be2, s2 = _knee(y + d - b, z - l1, l2, l3, pa[12])
    if abs(s2) < SINGULAR_TOL:
        return SING_LIMB2, z, geo
    psi = math.atan2(v, w)
    geo = (sin, cos, w, v, math.cos(psi), math.sin(psi),
           math.cos(al1), math.sin(al1), math.cos(be1), math.sin(be1), s1,
           math.cos(al2), math.sin(al2), math.cos(be2), math.sin(be2), s2,
           0.0, 0.0, 0.0, 0.0, 0.0)
    return OK, z, geo


@njit(cache=True)
def _motion(pa, geo, xd, y1d, y3d, xdd, y1dd, y3dd, vel, acc, rate, ang_acc):
    """Velocity and acceleration of every centre of mass (vel, acc: (bodies, 3)) and rate and
    acceleration of every swing angle (rate, ang_acc: (6,)) for slider rates and accelerations."""
    l2, l3, l4, l6 = pa[5], pa[6], pa[7], pa[9]
    sin, cos, w, v, cp, sp = geo[0], geo[1], geo[2], geo[3], geo[4], geo[5]
    ca1, sa1, cb1, sb1, s1 = geo[6], geo[7], geo[8], geo[9], geo[10]
    ca2, sa2, cb2, sb2, s2 = geo[11], geo[12], geo[13], geo[14], geo[15]
    # limb III and O' (_limb3_motion)
    v_d, v_dd = y1d - y3d, y1dd - y3dd
    den = w * l4 * sin
    th_d = (w * xd + v * v_d) / den
    w_d = xd - l4 * sin * th_d
    th_dd = (w_d ** 2 + v_d ** 2 + v * v_dd + w * (xdd - l4 * cos * th_d ** 2)) / den
    w_dd = xdd - l4 * cos * th_d ** 2 - l4 * sin * th_dd
    zd, zdd = l4 * cos * th_d, l4 * (cos * th_dd - sin * th_d ** 2)
    psi_d, psi_dd = (w * v_d - v * w_d) / l6 ** 2, (w * v_dd - v * w_dd) / l6 ** 2
    a1_d, a1_dd, b1_d, b1_dd = _knee_rates(xd, xdd, zd, zdd, ca1, sa1, cb1, sb1, s1, l2, l3)
    a2_d, a2_dd, b2_d, b2_dd = _knee_rates(y1d, y1dd, zd, zdd, ca2, sa2, cb2, sb2, s2, l2, l3)
    for k in range(_NB):
        for i in range(3):
            vel[k, i] = 0.0
            acc[k, i] = 0.0
    vel[0, 0], acc[0, 0] = xd, xdd                         # slider 2 (x_A2)
    vel[1, 1], acc[1, 1] = y1d, y1dd                       # slider 1 (y_A1)
    vel[2, 1], acc[2, 1] = y3d, y3dd                       # slider 3 (y_A3)
    # limb I in the (x, z) plane, riding on slider 1
    vu, vw, au, aw = _arm(a1_d, a1_dd, ca1, sa1, 0.5 * l2)
    vel[3, 0], vel[3, 1], vel[3, 2], acc[3, 0], acc[3, 1], acc[3, 2] = vu, y1d, vw, au, y1dd, aw
    cu, cw, cau, caw = _arm(a1_d, a1_dd, ca1, sa1, l2)
    vu, vw, au, aw = _arm(b1_d, b1_dd, cb1, sb1, 0.5 * l3)
    vel[4, 0], vel[4, 1], vel[4, 2], acc[4, 0], acc[4, 1], acc[4, 2] = cu + vu, y1d, cw + vw, cau + au, y1dd, caw + aw
    # limb II in the (y, z) plane, riding on slider 2
    vu, vw, au, aw = _arm(a2_d, a2_dd, ca2, sa2, 0.5 * l2)
    vel[5, 0], vel[5, 1], vel[5, 2], acc[5, 0], acc[5, 1], acc[5, 2] = xd, vu, vw, xdd, au, aw
    cu, cw, cau, caw = _arm(a2_d, a2_dd, ca2, sa2, l2)
    vu, vw, au, aw = _arm(b2_d, b2_dd, cb2, sb2, 0.5 * l3)
    vel[6, 0], vel[6, 1], vel[6, 2], acc[6, 0], acc[6, 1], acc[6, 2] = xd, cu + vu, cw + vw, xdd, cau + au, caw + aw
    # limb III in the (-x, z) plane, riding on slider 3; C3D3 translates with C3
    vu, vw, au, aw = _arm(th_d, th_dd, cos, sin, 0.5 * l4)
    vel[7, 0], vel[7, 1], vel[7, 2], acc[7, 0], acc[7, 1], acc[7, 2] = -vu, y3d, vw, -au, y3dd, aw
    cu, cw, cau, caw = _arm(th_d, th_dd, cos, sin, l4)
    vel[8, 0], vel[8, 1], vel[8, 2], acc[8, 0], acc[8, 1], acc[8, 2] = -cu, y3d, cw, -cau, y3dd, caw
    # D3E3 in the (x, y) plane from D3
    vu, vw, au, aw = _arm(psi_d, psi_dd, cp, sp, 0.5 * l6)
    vel[9, 0], vel[9, 1], vel[9, 2], acc[9, 0], acc[9, 1], acc[9, 2] = -cu + vu, y3d + vw, cw, -cau + au, y3dd + aw, caw
    vel[10, 0], vel[10, 1], vel[10, 2], acc[10, 0], acc[10, 1], acc[10, 2] = xd, y1d, zd, xdd, y1dd, zdd
    rate[0], rate[1], rate[2], rate[3], rate[4], rate[5] = a1_d, b1_d, a2_d, b2_d, th_d, psi_d
    ang_acc[0], ang_acc[1], ang_acc[2], ang_acc[3], ang_acc[4], ang_acc[5] = a1_dd, b1_dd, a2_dd, b2_dd, th_dd, psi_dd


@njit(cache=True)
def _finite3(x):
    return math.isfinite(x[0]) and math.isfinite(x[1]) and math.isfinite(x[2])


@njit(cache=True)
def terms(pa, rho, rho_dot, mode, M, bias, p):
    """M (3, 3) and bias (3,) of dynamics_terms and O' p (3,) for one state, written in place.
    Returns the status (OK, BAD_RHO, BAD_RHO_DOT, UNREACH_*, SING_*)."""
    if not _finite3(rho):
        return BAD_RHO
    if not _finite3(rho_dot):
        return BAD_RHO_DOT
    status, z, geo = _geometry(pa, rho, mode)
    if status != OK:
        return status
    p[0], p[1], p[2] = rho[0], rho[1] + pa[2], z
    vel, acc = np.empty((4, _NB, 3)), np.empty((4, _NB, 3))
    rate, ang_acc = np.empty((4, 6)), np.empty((4, 6))
    _motion(pa, geo, rho_dot[0], rho_dot[1], rho_dot[2], 0.0, 0.0, 0.0, vel[0], acc[0], rate[0], ang_acc[0])
    for j in range(3):   # unit slider rates: the velocity Jacobians
        _motion(pa, geo, 1.0 if j == 0 else 0.0, 1.0 if j == 1 else 0.0, 1.0 if j == 2 else 0.0, 0.0, 0.0, 0.0,
                vel[j + 1], acc[j + 1], rate[j + 1], ang_acc[j + 1])
    g = pa[10]
    for i in range(3):
        bias[i] = 0.0
        for j in range(3):
            M[i, j] = 0.0
    for k in range(_NB):
        m = pa[_M0 + k]
        a0, a1, a2 = acc[0, k, 0], acc[0, k, 1], acc[0, k, 2] + g
        for i in range(3):
            ji = vel[i + 1, k]
            bias[i] += m * (a0 * ji[0] + a1 * ji[1] + a2 * ji[2])
            for j in range(3):
                jj = vel[j + 1, k]
                M[i, j] += m * (ji[0] * jj[0] + ji[1] * jj[1] + ji[2] * jj[2])
    for k in range(6):
        inertia = pa[_I0 + k]
        for i in range(3):
            bias[i] += inertia * ang_acc[0, k] * rate[i + 1, k]
            for j in range(3):
                M[i, j] += inertia * rate[i + 1, k] * rate[j + 1, k]
    return OK


@njit(cache=True)
def slider_forces_kernel(pa, rho, rho_dot, rho_ddot, mode, out):
    """slider_forces = M rho_ddot + bias for one state, written into out (3,); returns the status."""
    if not _finite3(rho):
        return BAD_RHO
    if not _finite3(rho_dot):
        return BAD_RHO_DOT
    if not _finite3(rho_ddot):
        return BAD_RHO_DDOT
    M, bias, p = np.empty((3, 3)), np.empty(3), np.empty(3)
    status = terms(pa, rho, rho_dot, mode, M, bias, p)
    if status != OK:
        return status
    for i in range(3):
        out[i] = M[i, 0] * rho_ddot[0] + M[i, 1] * rho_ddot[1] + M[i, 2] * rho_ddot[2] + bias[i]
    return OK


@njit(cache=True)
def forward_dynamics_kernel(pa, rho, rho_dot, forces, mode, rho_ddot):
    """rho_ddot = M^-1 (forces - bias) written in place; returns the status."""
    if not _finite3(forces):
        return BAD_FORCE
    M, bias, p = np.empty((3, 3)), np.empty(3), np.empty(3)
    status = terms(pa, rho, rho_dot, mode, M, bias, p)
    if status != OK:
        return status
    for i in range(3):
        bias[i] = forces[i] - bias[i]
    if solve(M, bias, rho_ddot) == 0.0:
        return SING_MASS
    return OK


@njit(cache=True)
def rhs_kernel(pa, x, forces, mode):
    """(status, dx/dt) of the plant state x = (rho, rho_dot) under held slider forces."""
    xdot = np.empty(6)
    xdot[:3] = x[3:]
    status = forward_dynamics_kernel(pa, x[:3], x[3:], forces, mode, xdot[3:])
    return status, xdot


@njit(cache=True)
def advance_fixed(pa, x, forces, mode, rk4, substeps, dt):
    """x (6,) = (rho, rho_dot) advanced by ``substeps`` equal steps dt of classic RK4 (or
    explicit Euler) under held forces: plant.integrators.rk4 / euler with the same
    arithmetic, compiled. Works on a copy; returns (status, new x)."""
    x = x.copy()
    k1, k2, k3, k4, xs = np.empty(6), np.empty(6), np.empty(6), np.empty(6), np.empty(6)
    half, sixth = 0.5 * dt, dt / 6.0
    for n in range(substeps):
        status = forward_dynamics_kernel(pa, x[:3], x[3:], forces, mode, k1[3:])
        if status != OK:
            return status, x
        k1[:3] = x[3:]
        if not rk4:
            for i in range(6):
                x[i] = x[i] + dt * k1[i]
            continue
        for prev, kk, c in ((k1, k2, half), (k2, k3, half), (k3, k4, dt)):
            for i in range(6):
                xs[i] = x[i] + c * prev[i]
            status = forward_dynamics_kernel(pa, xs[:3], xs[3:], forces, mode, kk[3:])
            if status != OK:
                return status, x
            kk[:3] = xs[3:]
        for i in range(6):
            x[i] = x[i] + sixth * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
    return OK, x


@njit(cache=True)
def position_kernel(pa, rho, mode, p):
    """O' (3,) of assembly mode `mode` written in place; returns the status."""
    if not _finite3(rho):
        return BAD_RHO
    status, theta, z = _position(pa, rho[0], rho[1], rho[2], mode)
    p[0], p[1], p[2] = rho[0], rho[1] + pa[2], z
    return status


# ---------------------------------------------------------------- Python wrappers

_INVALID = {BAD_RHO: "rho contains NaN or inf", BAD_RHO_DOT: "rho_dot contains NaN or inf",
            BAD_FORCE: "slider forces contains NaN or inf", BAD_RHO_DDOT: "rho_ddot contains NaN or inf"}
_SINGULAR = {
    SING_SIN: "output singularity (paper 3.3, f33 = 0): sin theta = 0, D3C3 perpendicular to B3C3",
    SING_W: "output singularity (paper 3.3, f33 = 0): x - e + a + l4 cos theta = 0, E3 and C3 share x",
    SING_LIMB1: "limb I fully stretched or folded (|BD| = l2 +- l3)",
    SING_LIMB2: "limb II fully stretched or folded (|BD| = l2 +- l3)",
    SING_MASS: "mass matrix singular: no slider accelerations solve M rho_ddot = F - bias",
}
_UNREACHABLE = {
    UNREACH_D3E3: "eq. 10-11: l6^2 - (y_A1 + d - y_A3)^2 < 0 (D3E3 too short for the y offset)",
    UNREACH_LIMB1: "limb I cannot close: eq. 8 square root negative (|B1D1| outside [|l2 - l3|, l2 + l3])",
    UNREACH_LIMB2: "limb II cannot close: eq. 8 square root negative (|B2D2| outside [|l2 - l3|, l2 + l3])",
}


def raise_status(status, mode):
    """Raise the error plant.mechanism3t raises for a kernel status (nothing for OK)."""
    if status == OK:
        return
    if status in _INVALID:
        raise InvalidInputError(_INVALID[status])
    if status in _SINGULAR:
        raise SingularConfigurationError(_SINGULAR[status])
    if status == UNREACH_ARCCOS:
        sign = "+" if mode > 0 else "-"
        raise UnreachableError(f"eq. 11: arccos argument (N3 {sign} sqrt(l6^2 - N4^2))/l4 outside [-1, 1]")
    raise UnreachableError(_UNREACHABLE[status])


def _vector(name, value):
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3,):
        raise InvalidInputError(f"{name} has shape {arr.shape}, expected (3,)")
    return arr


def dynamics_terms(P, rho, rho_dot, mode=1):
    """(M (3, 3), bias (3,), O' (3,)) of one state: plant.mechanism3t.dynamics_terms compiled."""
    _check_mode(mode)
    M, bias, p = np.empty((3, 3)), np.empty(3), np.empty(3)
    raise_status(terms(_packed(P), _vector("rho", rho), _vector("rho_dot", rho_dot), mode, M, bias, p), mode)
    return M, bias, p


def slider_forces(P, rho, rho_dot, rho_ddot, mode=1):
    """plant.mechanism3t.slider_forces for one state, as M rho_ddot + bias."""
    _check_mode(mode)
    out = np.empty(3)
    raise_status(slider_forces_kernel(_packed(P), _vector("rho", rho), _vector("rho_dot", rho_dot),
                                      _vector("rho_ddot", rho_ddot), mode, out), mode)
    return out


def forward_dynamics(P, rho, rho_dot, forces, mode=1):
    """plant.mechanism3t.forward_dynamics for one state: rho_ddot = M^-1 (forces - bias)."""
    _check_mode(mode)
    out = np.empty(3)
    raise_status(forward_dynamics_kernel(_packed(P), _vector("rho", rho), _vector("rho_dot", rho_dot),
                                         _vector("slider forces", forces), mode, out), mode)
    return out


def forward_branch(P, rho, mode=1):
    """plant.mechanism3t.forward_branch for one rho (3,)."""
    _check_mode(mode)
    p = np.empty(3)
    raise_status(position_kernel(_packed(P), _vector("rho", rho), mode, p), mode)
    return p
