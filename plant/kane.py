"""Compiled Kane kernel of the hexapod: M, h, J per state, and the ID / FD solves.

Why compiled: numpy's fixed cost per call (~1 µs) times the ~200 small operations of one
state made a single inverse-dynamics call cost ~350 µs; the FMU calls forward dynamics
four times per RK4 substep. One numba loop over states does a state in ~1-2 µs and the
batched case at the same speed per state. Vectors are 3-tuples, so the loop allocates
nothing. The public, validated, batched API is plant.stewart; this module is its engine.

Equations (derivation in plant.stewart's docstring): generalised speeds u = (v, w) of {P}
relative to {B}, in {B};  M du/dt + h = J^T F.  A leg reduces to the 3x3 joint mass
K = m_m s s^T + k_t (1 - s s^T) acting on its platform-joint velocity v_a = v + w x rho.

The compiled code is cached on disk beside this file (numba cache=True): the first import
on a machine compiles for ~10 s, later imports load in well under a second.
"""
import numpy as np
from numba import njit

from .linalg import solve as linear_solve

ID, FD, TERMS = 0, 1, 2                      # what the kernel solves for
BASE_NONE, BASE_GRAVITY, BASE_FULL = 0, 1, 2  # how much base motion it keeps


@njit(cache=True)
def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(cache=True)
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True)
def _lin(ca, a, cb, b):
    """ca * a + cb * b for 3-tuples."""
    return (ca * a[0] + cb * b[0], ca * a[1] + cb * b[1], ca * a[2] + cb * b[2])


@njit(cache=True)
def _add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@njit(cache=True)
def _rotation(rpy, R):
    """R = Rz(yaw) Ry(pitch) Rx(roll) written into R (3x3)."""
    cr, sr = np.cos(rpy[0]), np.sin(rpy[0])
    cp, sp = np.cos(rpy[1]), np.sin(rpy[1])
    cy, sy = np.cos(rpy[2]), np.sin(rpy[2])
    R[0, 0], R[0, 1], R[0, 2] = cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr
    R[1, 0], R[1, 1], R[1, 2] = sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr
    R[2, 0], R[2, 1], R[2, 2] = -sp, cp * sr, cp * cr


@njit(cache=True)
def _mul(R, x):
    return (R[0, 0] * x[0] + R[0, 1] * x[1] + R[0, 2] * x[2],
            R[1, 0] * x[0] + R[1, 1] * x[1] + R[1, 2] * x[2],
            R[2, 0] * x[0] + R[2, 1] * x[1] + R[2, 2] * x[2])


@njit(cache=True)
def _mul_t(R, x):
    return (R[0, 0] * x[0] + R[1, 0] * x[1] + R[2, 0] * x[2],
            R[0, 1] * x[0] + R[1, 1] * x[1] + R[2, 1] * x[2],
            R[0, 2] * x[0] + R[1, 2] * x[1] + R[2, 2] * x[2])


@njit(cache=True)
def _omega(rpy, rate):
    """Angular velocity (parent frame) from RPY angles and rates."""
    cp, sp, cy, sy = np.cos(rpy[1]), np.sin(rpy[1]), np.cos(rpy[2]), np.sin(rpy[2])
    return (cy * cp * rate[0] - sy * rate[1], sy * cp * rate[0] + cy * rate[1], rate[2] - sp * rate[0])


@njit(cache=True)
def _omega_dot(rpy, rate, acc):
    """Angular acceleration: E acc + dE/dt rate."""
    cp, sp, cy, sy = np.cos(rpy[1]), np.sin(rpy[1]), np.cos(rpy[2]), np.sin(rpy[2])
    dr, dp, dy = rate[0], rate[1], rate[2]
    return ((-sy * dy * cp - cy * sp * dp) * dr + cy * cp * acc[0] - cy * dy * dp - sy * acc[1],
            (cy * dy * cp - sy * sp * dp) * dr + sy * cp * acc[0] - sy * dy * dp + cy * acc[1],
            -cp * dp * dr - sp * acc[0] + acc[2])


@njit(cache=True)
def _rpy_rate(rpy, w):
    """RPY rates from angular velocity: E^-1 w (singular at pitch = +-90 deg)."""
    cp, sp, cy, sy = np.cos(rpy[1]), np.sin(rpy[1]), np.cos(rpy[2]), np.sin(rpy[2])
    dr = (cy * w[0] + sy * w[1]) / cp
    return (dr, -sy * w[0] + cy * w[1], w[2] + sp * dr)


@njit(cache=True)
def kane(base_joints, platform_joints, data, pose, rate, arg, base_pose, base_rate, base_acc,
         base_mode, legs, twist_speeds, solve, M, h, J, ldot, length, out, det):
    """Fill M, h, J, leg rates for every state n and solve for ``out``.

    data = [m_p, I_p(3), m_f, l_f, m_m, l_m, I_axial, I_transverse, g].
    rate: RPY-angle rates, or the twist (v, w) when twist_speeds.
    arg: pose_acc (or twist acceleration) for ID, leg forces for FD.
    out: forces (ID) or pose_acc (twist acceleration when twist_speeds) (FD).
    length, ldot: leg lengths and rates.
    det: det(J) of each state, for the singularity check.
    """
    m_p, g0 = data[0], data[10]
    Ip = (data[1], data[2], data[3])
    mf, lf, mm, lm, Ia, It = data[4], data[5], data[6], data[7], data[8], data[9]
    R = np.empty((3, 3))
    Rb = np.empty((3, 3))
    A = np.empty((6, 6))
    b = np.empty(6)
    x = np.empty(6)
    zero = (0.0, 0.0, 0.0)
    for n in range(pose.shape[0]):
        _rotation(pose[n, 3:6], R)
        p = (pose[n, 0], pose[n, 1], pose[n, 2])
        v = (rate[n, 0], rate[n, 1], rate[n, 2])
        w = (rate[n, 3], rate[n, 4], rate[n, 5]) if twist_speeds else _omega(pose[n, 3:6], rate[n, 3:6])

        # base motion in {B}
        g, aB, wB, eB = (0.0, 0.0, -g0), zero, zero, zero
        if base_mode != BASE_NONE:
            _rotation(base_pose[n, 3:6], Rb)
            g = (-g0 * Rb[2, 0], -g0 * Rb[2, 1], -g0 * Rb[2, 2])
            if base_mode == BASE_FULL:
                aB = _mul_t(Rb, (base_acc[n, 0], base_acc[n, 1], base_acc[n, 2]))
                wB = _mul_t(Rb, _omega(base_pose[n, 3:6], base_rate[n, 3:6]))
                eB = _mul_t(Rb, _omega_dot(base_pose[n, 3:6], base_rate[n, 3:6], base_acc[n, 3:6]))

        # platform
        for i in range(6):
            for k in range(6):
                M[n, i, k] = 0.0
        for i in range(3):
            M[n, i, i] = m_p
            for k in range(3):
                M[n, 3 + i, 3 + k] = R[i, 0] * Ip[0] * R[k, 0] + R[i, 1] * Ip[1] * R[k, 1] \
                    + R[i, 2] * Ip[2] * R[k, 2]
        tr = _add(_lin(1.0, aB, -1.0, g), _add(_cross(eB, p), _cross(wB, _lin(1.0, _cross(wB, p), 2.0, v))))
        w_abs = _add(w, wB)
        Rt = _mul_t(R, w_abs)
        Iw_abs = _mul(R, (Ip[0] * Rt[0], Ip[1] * Rt[1], Ip[2] * Rt[2]))
        Rt = _mul_t(R, _add(eB, _cross(wB, w)))
        torque = _add(_mul(R, (Ip[0] * Rt[0], Ip[1] * Rt[1], Ip[2] * Rt[2])), _cross(w_abs, Iw_abs))
        for i in range(3):
            h[n, i] = m_p * tr[i]
            h[n, 3 + i] = torque[i]

        # legs
        for j in range(6):
            rho = _mul(R, (platform_joints[j, 0], platform_joints[j, 1], platform_joints[j, 2]))
            Bj = (base_joints[j, 0], base_joints[j, 1], base_joints[j, 2])
            L = (p[0] + rho[0] - Bj[0], p[1] + rho[1] - Bj[1], p[2] + rho[2] - Bj[2])
            l = np.sqrt(_dot(L, L))
            s = _lin(1.0 / l, L, 0.0, L)
            va = _add(v, _cross(w, rho))
            ld = _dot(s, va)
            sd = _lin(1.0 / l, va, -ld / l, s)
            rs = _cross(rho, s)
            ldot[n, j] = ld
            length[n, j] = l
            for k in range(3):
                J[n, j, k] = s[k]
                J[n, j, 3 + k] = rs[k]
            if not legs:
                continue
            aa0 = _cross(w, _cross(w, rho))
            ldd0 = _dot(s, aa0) + l * _dot(sd, sd)
            sdd0 = _lin(1.0 / l, aa0, -ldd0 / l, s)
            sdd0 = _lin(1.0, sdd0, -2.0 * ld / l, sd)
            lr = l - lm
            r_c = _lin(1.0, Bj, lf, s)
            r_m = _lin(1.0, Bj, lr, s)
            v_c = _lin(lf, sd, 0.0, sd)
            v_m = _lin(ld, s, lr, sd)
            tr_c = _add(_lin(1.0, aB, -1.0, g), _add(_cross(eB, r_c), _cross(wB, _lin(1.0, _cross(wB, r_c), 2.0, v_c))))
            tr_m = _add(_lin(1.0, aB, -1.0, g), _add(_cross(eB, r_m), _cross(wB, _lin(1.0, _cross(wB, r_m), 2.0, v_m))))
            f_c = _lin(mf * lf, sdd0, mf, tr_c)
            f_m = _add(_lin(mm * ldd0, s, 2.0 * mm * ld, sd), _lin(mm * lr, sdd0, mm, tr_m))
            w_rel = _cross(s, sd)
            w_leg = _add(w_rel, wB)
            alpha = _add(_cross(s, sdd0), _add(eB, _cross(wB, w_rel)))
            I_alpha = _lin(It, alpha, (Ia - It) * _dot(s, alpha), s)
            I_w = _lin(It, w_leg, (Ia - It) * _dot(s, w_leg), s)
            tau = _add(I_alpha, _cross(w_leg, I_w))
            fcs, fms = _dot(s, f_c), _dot(s, f_m)
            f = _add(_lin(lf / l, f_c, -lf / l * fcs, s), _lin(lr / l, f_m, fms * (1.0 - lr / l), s))
            f = _lin(1.0, f, 1.0 / l, _cross(tau, s))
            rf = _cross(rho, f)
            for k in range(3):
                h[n, k] += f[k]
                h[n, 3 + k] += rf[k]
            # joint mass: k_t A^T A + (m_m - k_t) j j^T with A = [1, -[rho]x]
            kt = (mf * lf * lf + mm * lr * lr + It) / (l * l)
            rr = _dot(rho, rho)
            for a in range(3):
                M[n, a, a] += kt
                M[n, 3 + a, 3 + a] += kt * rr
                for c in range(3):
                    M[n, 3 + a, 3 + c] -= kt * rho[a] * rho[c]
            # -kt [rho]x in the upper-right block, +kt [rho]x in the lower-left
            for a, c, val in ((0, 1, -rho[2]), (0, 2, rho[1]), (1, 0, rho[2]),
                              (1, 2, -rho[0]), (2, 0, -rho[1]), (2, 1, rho[0])):
                M[n, a, 3 + c] -= kt * val
                M[n, 3 + a, c] += kt * val
            cm = mm - kt
            for a in range(6):
                for c in range(6):
                    M[n, a, c] += cm * J[n, j, a] * J[n, j, c]

        if solve == ID:
            if twist_speeds:
                du = (arg[n, 0], arg[n, 1], arg[n, 2], arg[n, 3], arg[n, 4], arg[n, 5])
            else:
                wd = _omega_dot(pose[n, 3:6], rate[n, 3:6], arg[n, 3:6])
                du = (arg[n, 0], arg[n, 1], arg[n, 2], wd[0], wd[1], wd[2])
            for i in range(6):
                acc = h[n, i]
                for k in range(6):
                    acc += M[n, i, k] * du[k]
                    A[i, k] = J[n, k, i]
                b[i] = acc
            det[n] = linear_solve(A, b, x)
            out[n, :] = x
            continue
        for i in range(6):
            for k in range(6):
                A[i, k] = J[n, i, k]
            b[i] = 0.0
        det[n] = linear_solve(A, b, x)
        if solve == FD:
            for i in range(6):
                acc = -h[n, i]
                for k in range(6):
                    acc += J[n, k, i] * arg[n, k]
                    A[i, k] = M[n, i, k]
                b[i] = acc
            linear_solve(A, b, x)
            if twist_speeds:
                out[n, :] = x
            else:
                wd0 = _omega_dot(pose[n, 3:6], rate[n, 3:6], (0.0, 0.0, 0.0))
                rpy_acc = _rpy_rate(pose[n, 3:6], (x[3] - wd0[0], x[4] - wd0[1], x[5] - wd0[2]))
                out[n, 0], out[n, 1], out[n, 2] = x[0], x[1], x[2]
                out[n, 3], out[n, 4], out[n, 5] = rpy_acc


@njit(cache=True)
def _rhs(bj, pj, data, x, forces, base0, t0, t, base_mode, legs, base, M, h, J, ldot, length,
         out, det, dx):
    """dx/dt of the state x = [pose, twist] with the base extrapolated from base0 at t0
    (second-order Taylor); returns |det J|."""
    tau = t - t0
    for k in range(6):
        base[0, 0, k] = base0[0, k] + tau * base0[1, k] + 0.5 * tau * tau * base0[2, k]
        base[1, 0, k] = base0[1, k] + tau * base0[2, k]
        base[2, 0, k] = base0[2, k]
    kane(bj, pj, data, x[:6].reshape((1, 6)), x[6:].reshape((1, 6)), forces, base[0], base[1],
         base[2], base_mode, legs, True, FD, M, h, J, ldot, length, out, det)
    rpy_rate = _rpy_rate(x[3:6], (x[9], x[10], x[11]))
    for k in range(3):
        dx[k] = x[6 + k]
        dx[3 + k] = rpy_rate[k]
    for k in range(6):
        dx[6 + k] = out[0, k]
    return abs(det[0])


OK, BAD_INPUT, DIVERGED, STROKE = 0, 1, 2, 3   # advance_fixed status codes


@njit(cache=True)
def advance_fixed(rk4, substeps, bj, pj, data, x, inputs, t0, h, base_mode, legs, bounds, outputs):
    """Advance x = [pose, twist] over [t0, t0 + h] by ``substeps`` equal steps of classic
    RK4 (or explicit Euler), all compiled: the plant FMU's hot path, one call per
    communication step. The same methods as plant.integrators (a test holds them equal).

    inputs (4, 6): leg forces, base pose, base rate, base acc, held over the step.
    bounds (2, 6): lowest and highest leg lengths allowed (the stroke).
    Writes x in place and outputs (3, 6) = leg lengths, leg rates, pose rates at t0 + h.
    Returns (smallest |det J| met, status: OK, BAD_INPUT, DIVERGED or STROKE)."""
    for k in range(4):
        for j in range(6):
            if not np.isfinite(inputs[k, j]):
                return 0.0, BAD_INPUT
    forces, base0 = inputs[0:1], inputs[1:4]
    M, hb, J = np.empty((1, 6, 6)), np.empty((1, 6)), np.empty((1, 6, 6))
    ldot, length, out, det = np.empty((1, 6)), np.empty((1, 6)), np.empty((1, 6)), np.empty(1)
    base = np.empty((3, 1, 6))
    k1, k2, k3, k4, xs = np.empty(12), np.empty(12), np.empty(12), np.empty(12), np.empty(12)
    dt = h / substeps
    det_min = np.inf
    for n in range(substeps):
        t = t0 + n * dt
        det_min = min(det_min, _rhs(bj, pj, data, x, forces, base0, t0, t, base_mode, legs, base,
                                    M, hb, J, ldot, length, out, det, k1))
        if not rk4:
            x += dt * k1
            continue
        xs[:] = x + 0.5 * dt * k1
        det_min = min(det_min, _rhs(bj, pj, data, xs, forces, base0, t0, t + 0.5 * dt, base_mode,
                                    legs, base, M, hb, J, ldot, length, out, det, k2))
        xs[:] = x + 0.5 * dt * k2
        det_min = min(det_min, _rhs(bj, pj, data, xs, forces, base0, t0, t + 0.5 * dt, base_mode,
                                    legs, base, M, hb, J, ldot, length, out, det, k3))
        xs[:] = x + dt * k3
        det_min = min(det_min, _rhs(bj, pj, data, xs, forces, base0, t0, t + dt, base_mode, legs,
                                    base, M, hb, J, ldot, length, out, det, k4))
        x += dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    for k in range(12):
        if not np.isfinite(x[k]) or (k < 3 and abs(x[k]) > 100.0):
            return det_min, DIVERGED
    _leg_kinematics(bj, pj, x, outputs)
    status = OK
    for j in range(6):
        if outputs[0, j] < bounds[0, j] or outputs[0, j] > bounds[1, j]:
            status = STROKE
    return det_min, status


@njit(cache=True)
def _leg_kinematics(bj, pj, x, outputs):
    """outputs (3, 6) = leg lengths, leg rates and pose rates of x = [pose, twist]: the
    read-out after a step, kinematics only."""
    R = np.empty((3, 3))
    _rotation(x[3:6], R)
    v, w = (x[6], x[7], x[8]), (x[9], x[10], x[11])
    for j in range(6):
        rho = _mul(R, (pj[j, 0], pj[j, 1], pj[j, 2]))
        L = (x[0] + rho[0] - bj[j, 0], x[1] + rho[1] - bj[j, 1], x[2] + rho[2] - bj[j, 2])
        l = np.sqrt(_dot(L, L))
        outputs[0, j] = l
        outputs[1, j] = _dot(L, _add(v, _cross(w, rho))) / l
    rpy_rate = _rpy_rate(x[3:6], w)
    for k in range(3):
        outputs[2, k] = v[k]
        outputs[2, 3 + k] = rpy_rate[k]


@njit(cache=True)
def rhs(bj, pj, data, x, forces, base0, t0, t, base_mode, legs):
    """dx/dt and |det J| of one state: for implicit integrators and tests."""
    dx = np.empty(12)
    det = _rhs(bj, pj, data, x, forces, base0, t0, t, base_mode, legs, np.empty((3, 1, 6)),
               np.empty((1, 6, 6)), np.empty((1, 6)), np.empty((1, 6, 6)), np.empty((1, 6)),
               np.empty((1, 6)), np.empty((1, 6)), np.empty(1), dx)
    return dx, det
