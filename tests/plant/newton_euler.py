"""Independent reference inverse dynamics of the 6-UPS subreflector hexapod.

Method
------
Newton-Euler with explicit joint reactions, written entirely in the world
frame {W}, for all 13 bodies (platform, 6 cylinders, 6 rods).

1. Kinematics by Taylor-mode automatic differentiation ("jets").  Every pose
   coordinate q(t) = q + q_dot t + q_ddot t^2/2 (base and platform) is a
   truncated Taylor polynomial in time; rotation matrices, joint points,
   leg vectors, leg lengths and centres of mass are evaluated with jet
   arithmetic, so their first and second time derivatives at t = 0 are exact
   (to rounding).  Angular velocities are obtained from the rotation-matrix
   derivatives, omega = vee(R_dot R^T), and angular accelerations by
   differentiating the omega jet once more.  No Coriolis / transport /
   centripetal term is written by hand: they all come out of the chain rule
   applied to absolute world positions.  The legs follow the spec: absolute
   angular velocity omega_B + R_WB (s x s_dot) (s, s_dot in {B}), i.e. no spin
   about the leg relative to the base.

2. Dynamics.  For each body m (a - g) = sum of forces and
   I alpha + omega x (I omega) = sum of moments about its CoM, with
   g = (0, 0, -9.8) in {W}.  Unknowns, per leg (13):
     * U joint at B_i: force (3) + constraint torque tau_U s_i (1) that stops
       the spin about the leg,
     * prismatic joint: actuator force F_i along s_i (1), transverse force (2),
       full 3-vector torque (3); the wrench is referred to B_i (any point on
       the leg axis gives the same F_i),
     * S joint at a_i: force (3).
   78 unknowns, 78 scalar equations; solved by least squares, with the
   residual returned so that callers can check consistency.

Why it is independent of Kane's method
--------------------------------------
Kane's method (plant/hexapod/model.py) projects inertia and applied forces on
partial velocities in {B}, uses hand-derived transport/Coriolis terms of the
base motion (paper eqs. 5-30) and never sees the joint reactions.  Here no
partial velocity, no Jacobian, no relative-motion formula and no {B}-frame
fictitious force appears: the base motion enters only through the absolute
world trajectory of each body, the accelerations come from automatic
differentiation, and the actuator forces come from the equilibrium of
explicit reactions.  The geometry and mass tables are rebuilt here from the
spec (docs/conventions/stewart-6ups.md) and nothing is imported from plant/.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# --------------------------------------------------------------------------
# Tables (spec, Table 1 of the paper), SI units
# --------------------------------------------------------------------------
BASE_RADIUS = 2.060
PLATFORM_RADIUS = 1.555
BASE_ANGLES_DEG = (85.0, 95.0, 205.0, 215.0, 325.0, 335.0)
PLATFORM_ANGLES_DEG = (35.0, 145.0, 155.0, 265.0, 275.0, 25.0)


@dataclass(frozen=True)
class Table:
    d: float = 0.0
    platform_mass: float = 2129.7
    platform_inertia: np.ndarray = field(
        default_factory=lambda: np.diag([3683.0, 3683.0, 6474.0]))
    cylinder_mass: float = 299.8
    cylinder_com: float = 0.766842          # l_f, from B_i along the leg
    cylinder_inertia: tuple = (4.3, 112.6, 112.6)   # axial, transverse, transverse
    rod_mass: float = 85.91
    rod_com: float = 0.806132               # l_m, from a_i back along the leg
    rod_inertia: tuple = (0.3, 18.28, 18.28)
    gravity: float = 9.8

    @property
    def base_joints(self) -> np.ndarray:
        a = np.deg2rad(BASE_ANGLES_DEG)
        return np.stack([BASE_RADIUS * np.cos(a), BASE_RADIUS * np.sin(a),
                         np.zeros(6)], axis=1)

    @property
    def platform_joints(self) -> np.ndarray:
        a = np.deg2rad(PLATFORM_ANGLES_DEG)
        return np.stack([PLATFORM_RADIUS * np.cos(a), PLATFORM_RADIUS * np.sin(a),
                         np.full(6, self.d)], axis=1)


PAPER = Table()

# --------------------------------------------------------------------------
# Taylor jets: c[k] = (d^k f / dt^k)(0) / k!
# --------------------------------------------------------------------------
ORDER = 3   # coefficients 0, 1, 2: enough for accelerations at t = 0


class Jet:
    __slots__ = ("c",)

    def __init__(self, c):
        self.c = np.asarray(c, dtype=float)

    # construction ---------------------------------------------------------
    @staticmethod
    def const(x, K=ORDER):
        x = np.asarray(x, dtype=float)
        c = np.zeros((K,) + x.shape)
        c[0] = x
        return Jet(c)

    @staticmethod
    def motion(q, qd, qdd, K=ORDER):
        """q + qd t + qdd t^2 / 2."""
        q = np.asarray(q, dtype=float)
        c = np.zeros((K,) + q.shape)
        c[0] = q
        c[1] = qd
        c[2] = 0.5 * np.asarray(qdd, dtype=float)
        return Jet(c)

    @staticmethod
    def stack(jets, axis=0):
        jets = [j if isinstance(j, Jet) else Jet.const(j) for j in jets]
        K = min(len(j.c) for j in jets)
        ax = axis if axis < 0 else axis + 1
        return Jet(np.stack([j.c[:K] for j in jets], axis=ax))

    # helpers ---------------------------------------------------------------
    @property
    def K(self):
        return self.c.shape[0]

    @staticmethod
    def _pair(a, b):
        if not isinstance(b, Jet):
            b = Jet.const(b, a.K)
        K = min(a.K, b.K)
        return a.c[:K], b.c[:K], K

    def __getitem__(self, idx):
        if not isinstance(idx, tuple):
            idx = (idx,)
        return Jet(self.c[(slice(None),) + idx])

    @property
    def T(self):
        return Jet(np.swapaxes(self.c, -1, -2))

    # arithmetic ------------------------------------------------------------
    def __add__(self, o):
        a, b, _ = Jet._pair(self, o)
        return Jet(a + b)

    __radd__ = __add__

    def __sub__(self, o):
        a, b, _ = Jet._pair(self, o)
        return Jet(a - b)

    def __rsub__(self, o):
        a, b, _ = Jet._pair(self, o)
        return Jet(b - a)

    def __neg__(self):
        return Jet(-self.c)

    def _cauchy(self, o, op):
        a, b, K = Jet._pair(self, o)
        return Jet(np.stack([sum(op(a[j], b[k - j]) for j in range(k + 1))
                             for k in range(K)]))

    def __mul__(self, o):
        if not isinstance(o, Jet):
            return Jet(self.c * np.asarray(o, dtype=float))
        return self._cauchy(o, np.multiply)

    __rmul__ = __mul__

    def __truediv__(self, o):
        if not isinstance(o, Jet):
            return Jet(self.c / np.asarray(o, dtype=float))
        return self * o.recip()

    def __matmul__(self, o):
        return self._cauchy(o, np.matmul)

    def __rmatmul__(self, o):       # constant @ jet
        return Jet.const(o, self.K)._cauchy(self, np.matmul)

    def cross(self, o):
        return self._cauchy(o, lambda x, y: np.cross(x, y))

    def dot(self, o):
        return self._cauchy(o, lambda x, y: np.sum(x * y, axis=-1))

    # elementary functions ----------------------------------------------------
    def recip(self):
        x = self.c
        y = np.zeros_like(x)
        y[0] = 1.0 / x[0]
        for k in range(1, self.K):
            y[k] = -sum(x[j] * y[k - j] for j in range(1, k + 1)) / x[0]
        return Jet(y)

    def sqrt(self):
        x = self.c
        y = np.zeros_like(x)
        y[0] = np.sqrt(x[0])
        for k in range(1, self.K):
            y[k] = (x[k] - sum(y[j] * y[k - j] for j in range(1, k))) / (2.0 * y[0])
        return Jet(y)

    def sincos(self):
        u = self.c
        s = np.zeros_like(u)
        c = np.zeros_like(u)
        s[0], c[0] = np.sin(u[0]), np.cos(u[0])
        for k in range(1, self.K):
            s[k] = sum(j * u[j] * c[k - j] for j in range(1, k + 1)) / k
            c[k] = -sum(j * u[j] * s[k - j] for j in range(1, k + 1)) / k
        return Jet(s), Jet(c)

    # calculus ---------------------------------------------------------------
    def deriv(self):
        k = np.arange(1, self.K).reshape((-1,) + (1,) * (self.c.ndim - 1))
        return Jet(self.c[1:] * k)

    def val(self):
        return self.c[0]

    def d1(self):
        return self.c[1]

    def d2(self):
        return 2.0 * self.c[2]


def _rot_x(a: Jet) -> Jet:
    s, c = a.sincos()
    return Jet.stack([Jet.stack([1.0, 0.0, 0.0]),
                      Jet.stack([0.0, c, -s]),
                      Jet.stack([0.0, s, c])])


def _rot_y(a: Jet) -> Jet:
    s, c = a.sincos()
    return Jet.stack([Jet.stack([c, 0.0, s]),
                      Jet.stack([0.0, 1.0, 0.0]),
                      Jet.stack([-s, 0.0, c])])


def _rot_z(a: Jet) -> Jet:
    s, c = a.sincos()
    return Jet.stack([Jet.stack([c, -s, 0.0]),
                      Jet.stack([s, c, 0.0]),
                      Jet.stack([0.0, 0.0, 1.0])])


def rpy_matrix(angles: Jet) -> Jet:
    """R = Rz(yaw) Ry(pitch) Rx(roll), angles = [roll, pitch, yaw]."""
    return _rot_z(angles[2]) @ _rot_y(angles[1]) @ _rot_x(angles[0])


def _vee_skew(M: Jet) -> Jet:
    S = (M - M.T) * 0.5
    return Jet.stack([S[2, 1], S[0, 2], S[1, 0]])


def _angular(R: Jet):
    """(omega, alpha) in the frame in which R's columns are expressed."""
    w = _vee_skew(R.deriv() @ R.T)         # omega = vee(R_dot R^T)
    return w.val(), w.d1()


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _perp_basis(s):
    """Two unit vectors completing s to an orthonormal basis."""
    t = np.array([1.0, 0.0, 0.0]) if abs(s[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(s, t)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(s, e1)
    return e1, e2


def _as6(x):
    if x is None:
        return np.zeros(6)
    x = np.asarray(x, dtype=float)
    return np.zeros(6) if x.ndim == 0 and x == 0 else np.broadcast_to(x, (6,)).astype(float)


# --------------------------------------------------------------------------
# Kinematics of all bodies in {W}
# --------------------------------------------------------------------------
def world_kinematics(pose, pose_rate, pose_acc, base_pose=None, base_rate=None,
                     base_acc=None, table: Table = PAPER):
    """Absolute kinematics of the 13 bodies, everything in {W}.

    Returns a dict with, for 'platform', 'cyl' and 'rod': r, v, a (CoM) and
    R (orientation / leg axis data), omega, alpha, and per-leg A_i, B_i, s_i,
    l_i, l_dot_i (world vectors, leg data in {W}).
    """
    qb = Jet.motion(_as6(base_pose), _as6(base_rate), _as6(base_acc))
    qp = Jet.motion(_as6(pose), _as6(pose_rate), _as6(pose_acc))
    R_WB = rpy_matrix(qb[3:])
    R_BP = rpy_matrix(qp[3:])
    p_B = qb[:3]
    R_WP = R_WB @ R_BP

    out = {}
    r_P = p_B + R_WB @ qp[:3]
    w_P, al_P = _angular(R_WP)
    w_B, al_B = _angular(R_WB)
    out["platform"] = dict(r=r_P.val(), v=r_P.d1(), a=r_P.d2(),
                           R=R_WP.val(), omega=w_P, alpha=al_P)
    out["base"] = dict(R=R_WB.val(), omega=w_B, alpha=al_B, r=p_B.val())

    legs = []
    for i in range(6):
        Bi = Jet.const(table.base_joints[i])
        ai = Jet.const(table.platform_joints[i])
        A_in_B = qp[:3] + R_BP @ ai              # joint a_i in {B}
        L_in_B = A_in_B - Bi
        l = L_in_B.dot(L_in_B).sqrt()
        s_in_B = L_in_B / l
        # leg's absolute angular velocity: omega_B + R_WB (s x s_dot) in {B}
        w_rel_B = s_in_B.cross(s_in_B.deriv())
        w_leg = R_WB.deriv() @ R_WB.T            # -> omega_B via vee below
        w_leg = _vee_skew(w_leg) + R_WB @ w_rel_B
        s_W = R_WB @ s_in_B
        B_W = p_B + R_WB @ Bi
        A_W = p_B + R_WB @ A_in_B
        r_c = B_W + s_W * table.cylinder_com
        r_r = B_W + s_W * (l - table.rod_com)
        legs.append(dict(
            s=s_W.val(), l=l.val(), l_dot=l.d1(), B=B_W.val(), B_v=B_W.d1(),
            A=A_W.val(),
            omega=w_leg.val(), alpha=w_leg.d1(),
            cyl=dict(r=r_c.val(), v=r_c.d1(), a=r_c.d2()),
            rod=dict(r=r_r.val(), v=r_r.d1(), a=r_r.d2()),
        ))
    out["legs"] = legs
    return out


def leg_inertia(s, axial, transverse):
    P = np.outer(s, s)
    return axial * P + transverse * (np.eye(3) - P)


# --------------------------------------------------------------------------
# Newton-Euler with explicit reactions
# --------------------------------------------------------------------------
def inverse_dynamics_single(pose, pose_rate, pose_acc, base_pose=None,
                            base_rate=None, base_acc=None, table: Table = PAPER,
                            gravity_w=None, return_residual=False):
    """Six actuator forces F_i (positive = extending, pushes platform away)."""
    kin = world_kinematics(pose, pose_rate, pose_acc, base_pose, base_rate,
                           base_acc, table)
    g = (np.array([0.0, 0.0, -table.gravity]) if gravity_w is None
         else np.asarray(gravity_w, dtype=float))

    n_leg_unk = 13
    # unknown layout per leg i (offset 13 i):
    #  0:3  f_U   force of base on cylinder at B_i
    #  3    tau_U torque of base on cylinder along s_i
    #  4    F     actuator force on rod along s_i (from cylinder)
    #  5:7  t1,t2 transverse prismatic force on rod (from cylinder)
    #  7:10 M     prismatic torque on rod (from cylinder), wrench referred to B_i
    #  10:13 f_S  force of rod on platform at a_i
    nu = 6 * n_leg_unk
    # equations: platform (6), then per leg cylinder (6) and rod (6)
    A = np.zeros((6 + 12 * 6, nu))
    b = np.zeros(6 + 12 * 6)

    def body_rhs(m, a, I, alpha, omega):
        return np.concatenate([m * (a - g), I @ alpha + np.cross(omega, I @ omega)])

    plat = kin["platform"]
    Ip = plat["R"] @ table.platform_inertia @ plat["R"].T
    b[0:6] = body_rhs(table.platform_mass, plat["a"], Ip, plat["alpha"], plat["omega"])
    rP = plat["r"]

    for i, leg in enumerate(kin["legs"]):
        o = n_leg_unk * i
        s, Bw, Aw = leg["s"], leg["B"], leg["A"]
        e1, e2 = _perp_basis(s)
        # platform: force f_S at A_i
        A[0:3, o + 10:o + 13] += np.eye(3)
        A[3:6, o + 10:o + 13] += _skew(Aw - rP)

        # prismatic wrench on the rod (force f_P at B_i + moment M about B_i)
        fP_cols = np.zeros((3, nu))
        fP_cols[:, o + 4] = s
        fP_cols[:, o + 5] = e1
        fP_cols[:, o + 6] = e2
        M_cols = np.zeros((3, nu))
        M_cols[:, o + 7:o + 10] = np.eye(3)

        # cylinder ---------------------------------------------------------
        rc = leg["cyl"]["r"]
        ec = 6 + 12 * i
        Fc = np.zeros((3, nu))
        Fc[:, o:o + 3] = np.eye(3)               # f_U
        Fc -= fP_cols                            # reaction of the prismatic joint
        Tc = np.zeros((3, nu))
        Tc[:, o:o + 3] = _skew(Bw - rc)          # f_U at B_i
        Tc[:, o + 3] = s                         # tau_U s
        Tc -= M_cols + _skew(Bw - rc) @ fP_cols  # -(M + (B - rc) x f_P)
        A[ec:ec + 3] = Fc
        A[ec + 3:ec + 6] = Tc
        Ic = leg_inertia(s, table.cylinder_inertia[0], table.cylinder_inertia[1])
        b[ec:ec + 6] = body_rhs(table.cylinder_mass, leg["cyl"]["a"], Ic,
                                leg["alpha"], leg["omega"])

        # rod ------------------------------------------------------------------
        rr = leg["rod"]["r"]
        er = ec + 6
        Fr = fP_cols.copy()
        Fr[:, o + 10:o + 13] -= np.eye(3)        # -f_S at A_i
        Tr = M_cols + _skew(Bw - rr) @ fP_cols
        Tr[:, o + 10:o + 13] -= _skew(Aw - rr)
        A[er:er + 3] = Fr
        A[er + 3:er + 6] = Tr
        Ir = leg_inertia(s, table.rod_inertia[0], table.rod_inertia[1])
        b[er:er + 6] = body_rhs(table.rod_mass, leg["rod"]["a"], Ir,
                                leg["alpha"], leg["omega"])

    x, *_ = np.linalg.lstsq(A, b, rcond=None)
    F = x[4::n_leg_unk].copy()
    if return_residual:
        res = np.linalg.norm(A @ x - b) / max(np.linalg.norm(b), 1e-300)
        return F, res, x, kin
    return F


def inverse_dynamics(pose, pose_rate, pose_acc, base_pose=None, base_rate=None,
                     base_acc=None, table: Table = PAPER, gravity_w=None):
    """Batched wrapper (plain loop) over the leading dimensions of pose."""
    pose = np.asarray(pose, dtype=float)
    lead = pose.shape[:-1]

    def bc(x):
        if x is None:
            return np.zeros(lead + (6,))
        return np.broadcast_to(np.asarray(x, dtype=float), lead + (6,))

    arrs = [bc(a) for a in (pose, pose_rate, pose_acc, base_pose, base_rate, base_acc)]
    flat = [a.reshape(-1, 6) for a in arrs]
    out = np.array([inverse_dynamics_single(*(f[k] for f in flat), table=table,
                                            gravity_w=gravity_w)
                    for k in range(flat[0].shape[0])])
    return out.reshape(lead + (6,))


def energy_rate(kin, table: Table = PAPER, gravity_w=None):
    """d/dt (kinetic + potential energy) of all 13 bodies, world frame; with a
    fixed base it must equal the actuator power sum_i F_i l_dot_i."""
    g = (np.array([0.0, 0.0, -table.gravity]) if gravity_w is None
         else np.asarray(gravity_w, dtype=float))
    plat = kin["platform"]
    Ip = plat["R"] @ table.platform_inertia @ plat["R"].T
    dE = (table.platform_mass * plat["v"] @ (plat["a"] - g)
          + plat["omega"] @ Ip @ plat["alpha"])
    for leg in kin["legs"]:
        for part, m, inert in (("cyl", table.cylinder_mass, table.cylinder_inertia),
                               ("rod", table.rod_mass, table.rod_inertia)):
            I = leg_inertia(leg["s"], inert[0], inert[1])
            dE += m * leg[part]["v"] @ (leg[part]["a"] - g) + leg["omega"] @ I @ leg["alpha"]
    return dE


def base_power(x, kin):
    """Power delivered by the base to the legs through the U joints (force at
    B_i, a point of the base, plus the spin-stopping torque along s_i), from
    the reaction vector x of inverse_dynamics_single(..., return_residual=True).
    With a moving base: sum_i F_i l_dot_i + base_power = energy_rate."""
    w_B = kin["base"]["omega"]
    P = 0.0
    for i, leg in enumerate(kin["legs"]):
        o = 13 * i
        P += x[o:o + 3] @ leg["B_v"] + x[o + 3] * (leg["s"] @ w_B)
    return P
