/* Kane kernel of the 6-UPS hexapod (API and conventions in hexapod.h).

   A port, term by term and in the same operation order, of the numba kernel it replaced
   (git 73017ff:plant/hexapod/kernel.py), so that both round alike (tests/plant/test_hexapod_kernel.py holds them
   equal). Vectors are 3-element structs passed by value and all scratch lives on the
   stack: nothing is allocated. The legs are computed two at a time, one per lane of a
   2-double vector, with each lane's operations those of one leg: the same bits. Equations: M du/dt + h = J^T F with u = (v, w) of {P}
   relative to {B} in {B}; a leg reduces to the 3x3 joint mass
   K = m_m s s^T + k_t (1 - s s^T) acting on its platform-joint velocity v_a = v + w x rho. */
#include <math.h>
#include <stddef.h>
#include "hexapod.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif
#include "linalg.h"

typedef struct { double e[3]; } v3;

static inline v3 vec(double a, double b, double c) { v3 r = {{a, b, c}}; return r; }

static inline v3 load(const double *x) { return vec(x[0], x[1], x[2]); }

static inline v3 cross(v3 a, v3 b)
{
    return vec(a.e[1] * b.e[2] - a.e[2] * b.e[1], a.e[2] * b.e[0] - a.e[0] * b.e[2],
               a.e[0] * b.e[1] - a.e[1] * b.e[0]);
}

static inline double dot(v3 a, v3 b) { return a.e[0] * b.e[0] + a.e[1] * b.e[1] + a.e[2] * b.e[2]; }

/* ca * a + cb * b */
static inline v3 lin(double ca, v3 a, double cb, v3 b)
{
    return vec(ca * a.e[0] + cb * b.e[0], ca * a.e[1] + cb * b.e[1], ca * a.e[2] + cb * b.e[2]);
}

static inline v3 add(v3 a, v3 b) { return vec(a.e[0] + b.e[0], a.e[1] + b.e[1], a.e[2] + b.e[2]); }

/* cos and sin of RPY angles, taken once per angle set: the rotation, the angular
   velocity and acceleration and the RPY rates of one pose all read them. */
typedef struct { double cr, sr, cp, sp, cy, sy; } trig;

static inline trig angles(const double *rpy)
{
    trig t = {cos(rpy[0]), sin(rpy[0]), cos(rpy[1]), sin(rpy[1]), cos(rpy[2]), sin(rpy[2])};
    return t;
}

/* R = Rz(yaw) Ry(pitch) Rx(roll), row-major 3x3. */
static inline void rotation(const trig *t, double *R)
{
    double cr = t->cr, sr = t->sr, cp = t->cp, sp = t->sp, cy = t->cy, sy = t->sy;
    R[0] = cy * cp; R[1] = cy * sp * sr - sy * cr; R[2] = cy * sp * cr + sy * sr;
    R[3] = sy * cp; R[4] = sy * sp * sr + cy * cr; R[5] = sy * sp * cr - cy * sr;
    R[6] = -sp;     R[7] = cp * sr;                R[8] = cp * cr;
}

static inline v3 mul(const double *R, v3 x)
{
    return vec(R[0] * x.e[0] + R[1] * x.e[1] + R[2] * x.e[2],
               R[3] * x.e[0] + R[4] * x.e[1] + R[5] * x.e[2],
               R[6] * x.e[0] + R[7] * x.e[1] + R[8] * x.e[2]);
}

static inline v3 mul_t(const double *R, v3 x)
{
    return vec(R[0] * x.e[0] + R[3] * x.e[1] + R[6] * x.e[2],
               R[1] * x.e[0] + R[4] * x.e[1] + R[7] * x.e[2],
               R[2] * x.e[0] + R[5] * x.e[1] + R[8] * x.e[2]);
}

/* Angular velocity (parent frame) from RPY angles and rates. */
static inline v3 omega(const trig *t, const double *rate)
{
    double cp = t->cp, sp = t->sp, cy = t->cy, sy = t->sy;
    return vec(cy * cp * rate[0] - sy * rate[1], sy * cp * rate[0] + cy * rate[1], rate[2] - sp * rate[0]);
}

/* Angular acceleration: E acc + dE/dt rate. */
static inline v3 omega_dot(const trig *t, const double *rate, const double *acc)
{
    double cp = t->cp, sp = t->sp, cy = t->cy, sy = t->sy;
    double dr = rate[0], dp = rate[1], dy = rate[2];
    return vec((-sy * dy * cp - cy * sp * dp) * dr + cy * cp * acc[0] - cy * dy * dp - sy * acc[1],
               (cy * dy * cp - sy * sp * dp) * dr + sy * cp * acc[0] - sy * dy * dp + cy * acc[1],
               -cp * dp * dr - sp * acc[0] + acc[2]);
}

/* RPY rates from angular velocity: E^-1 w (singular at pitch = +-90 deg). */
static inline v3 rpy_rate(const trig *t, v3 w)
{
    double cp = t->cp, sp = t->sp, cy = t->cy, sy = t->sy;
    double dr = (cy * w.e[0] + sy * w.e[1]) / cp;
    return vec(dr, -sy * w.e[0] + cy * w.e[1], w.e[2] + sp * dr);
}

/* Translational acceleration terms of a point r moving at v_rel in {B}, base motion
   included: a_B - g + eB x r + wB x (wB x r + 2 v_rel). */
static inline v3 transport(v3 aB, v3 g, v3 eB, v3 wB, v3 r, v3 v_rel)
{
    return add(lin(1.0, aB, -1.0, g), add(cross(eB, r), cross(wB, lin(1.0, cross(wB, r), 2.0, v_rel))));
}

/* What the base motion contributes, in {B}: gravity g, the base's acceleration aB, angular
   velocity wB and angular acceleration eB (zero where base_mode leaves them out). */
typedef struct { v3 g, aB, wB, eB; } base_frame;

static base_frame base_terms(int base_mode, double g0, const double *base_pose, const double *base_rate,
                             const double *base_acc, int n)
{
    const v3 zero = vec(0.0, 0.0, 0.0);
    base_frame f = {vec(0.0, 0.0, -g0), zero, zero, zero};
    if (base_mode != MB_HEXAPOD_BASE_NONE) {
        const double *bp = base_pose + 6 * n, *br = base_rate + 6 * n, *ba = base_acc + 6 * n;
        double Rb[9];
        const trig tb = angles(bp + 3);
        rotation(&tb, Rb);
        f.g = vec(-g0 * Rb[6], -g0 * Rb[7], -g0 * Rb[8]);
        if (base_mode == MB_HEXAPOD_BASE_FULL) {
            f.aB = mul_t(Rb, load(ba));
            f.wB = mul_t(Rb, omega(&tb, br + 3));
            f.eB = mul_t(Rb, omega_dot(&tb, br + 3, ba + 3));
        }
    }
    return f;
}

/* Two legs at a time: d2 holds one double per leg, and every operation below acts on
   each lane alone, as the scalar operation would (IEEE results per lane: the same bits).
   GCC and clang keep a pair in one SSE2 / NEON register; other compilers get the pair
   as two doubles. */
#if defined(__GNUC__)
typedef double d2 __attribute__((vector_size(16)));
static inline d2 dadd(d2 a, d2 b) { return a + b; }
static inline d2 dsub(d2 a, d2 b) { return a - b; }
static inline d2 dmul(d2 a, d2 b) { return a * b; }
static inline d2 ddiv(d2 a, d2 b) { return a / b; }
static inline d2 dneg(d2 a) { return -a; }
static inline double lane(d2 a, int i) { return a[i]; }
static inline d2 pair(double a, double b) { d2 r = {a, b}; return r; }
#define ALWAYS_INLINE static inline __attribute__((always_inline))
#else
typedef struct { double v[2]; } d2;
static inline d2 dadd(d2 a, d2 b) { d2 r = {{a.v[0] + b.v[0], a.v[1] + b.v[1]}}; return r; }
static inline d2 dsub(d2 a, d2 b) { d2 r = {{a.v[0] - b.v[0], a.v[1] - b.v[1]}}; return r; }
static inline d2 dmul(d2 a, d2 b) { d2 r = {{a.v[0] * b.v[0], a.v[1] * b.v[1]}}; return r; }
static inline d2 ddiv(d2 a, d2 b) { d2 r = {{a.v[0] / b.v[0], a.v[1] / b.v[1]}}; return r; }
static inline d2 dneg(d2 a) { d2 r = {{-a.v[0], -a.v[1]}}; return r; }
static inline double lane(d2 a, int i) { return a.v[i]; }
static inline d2 pair(double a, double b) { d2 r = {{a, b}}; return r; }
#define ALWAYS_INLINE static inline
#endif

static inline d2 splat(double a) { return pair(a, a); }

static inline d2 dsqrt(d2 a) { return pair(sqrt(lane(a, 0)), sqrt(lane(a, 1))); }

/* A 3-vector per lane: v3 of two legs. */
typedef struct { d2 x, y, z; } w3;

static inline w3 wvec(d2 a, d2 b, d2 c) { w3 r = {a, b, c}; return r; }

static inline w3 wsplat(v3 a) { return wvec(splat(a.e[0]), splat(a.e[1]), splat(a.e[2])); }

/* rows j and j + 1 of a (6, 3) array */
static inline w3 wload(const double *x, int j)
{
    return wvec(pair(x[3 * j], x[3 * j + 3]), pair(x[3 * j + 1], x[3 * j + 4]), pair(x[3 * j + 2], x[3 * j + 5]));
}

static inline w3 wcross(w3 a, w3 b)
{
    return wvec(dsub(dmul(a.y, b.z), dmul(a.z, b.y)), dsub(dmul(a.z, b.x), dmul(a.x, b.z)),
                dsub(dmul(a.x, b.y), dmul(a.y, b.x)));
}

static inline d2 wdot(w3 a, w3 b) { return dadd(dadd(dmul(a.x, b.x), dmul(a.y, b.y)), dmul(a.z, b.z)); }

/* ca * a + cb * b */
static inline w3 wlin(d2 ca, w3 a, d2 cb, w3 b)
{
    return wvec(dadd(dmul(ca, a.x), dmul(cb, b.x)), dadd(dmul(ca, a.y), dmul(cb, b.y)),
                dadd(dmul(ca, a.z), dmul(cb, b.z)));
}

static inline w3 wadd(w3 a, w3 b) { return wvec(dadd(a.x, b.x), dadd(a.y, b.y), dadd(a.z, b.z)); }

static inline w3 wmul(const double *R, w3 x)
{
    return wvec(dadd(dadd(dmul(splat(R[0]), x.x), dmul(splat(R[1]), x.y)), dmul(splat(R[2]), x.z)),
                dadd(dadd(dmul(splat(R[3]), x.x), dmul(splat(R[4]), x.y)), dmul(splat(R[5]), x.z)),
                dadd(dadd(dmul(splat(R[6]), x.x), dmul(splat(R[7]), x.y)), dmul(splat(R[8]), x.z)));
}

static inline v3 pick(w3 a, int i) { return vec(lane(a.x, i), lane(a.y, i), lane(a.z, i)); }

/* transport of two points (aB - g and the base vectors are splat) */
static inline w3 wtransport(w3 aB, w3 g, w3 eB, w3 wB, w3 r, w3 v_rel)
{
    return wadd(wlin(splat(1.0), aB, splat(-1.0), g),
                wadd(wcross(eB, r), wcross(wB, wlin(splat(1.0), wcross(wB, r), splat(2.0), v_rel))));
}

/* The legs' terms of M added to it: for each leg in turn its reflected mass m_r J_j^T J_j
   (m_r != 0), and with massive legs its joint mass k_t A^T A + (m_m - k_t) J_j^T J_j with
   A = [1, -[rho]x] (k_t on the upper-left diagonal, k_t (rho.rho - rho rho^T) lower right,
   -k_t [rho]x upper right, +k_t [rho]x lower left). Entry by entry the additions of one
   leg after another, as a leg at a time adds them; but each pair of columns of M is held
   in a register over all six legs (one load and store instead of one per term), and a
   lane without a term adds -0.0 or subtracts +0.0, which leave every number as it is. */
ALWAYS_INLINE void leg_mass_of(double *M, const double *J, int reflected, double m_r, int legs, double mm,
                               const double *kt, const double *rr, const double *rho)
{
    const double m0 = -0.0, p0 = 0.0;
#pragma GCC unroll 6
    for (int a = 0; a < 6; a++) {
#pragma GCC unroll 3
        for (int k = 0; k < 6; k += 2) {
            d2 acc = pair(M[6 * a + k], M[6 * a + k + 1]);
#pragma GCC unroll 6
            for (int j = 0; j < 6; j++) {
                const double *Jj = J + 6 * j;
                const d2 Jp = pair(Jj[k], Jj[k + 1]);
                if (reflected) acc = dadd(acc, dmul(splat(m_r * Jj[a]), Jp));
                if (!legs) continue;
                const double t = kt[j], r0 = rho[3 * j], r1 = rho[3 * j + 1], r2 = rho[3 * j + 2];
                switch (6 * a + k) {   /* the joint mass of row a, columns k and k + 1 */
                case 0: acc = dadd(acc, pair(t, m0)); break;
                case 4: acc = dsub(acc, pair(t * -r2, t * r1)); break;
                case 6: acc = dadd(acc, pair(m0, t)); break;
                case 8: acc = dsub(acc, pair(p0, t * r2)); break;
                case 10: acc = dsub(acc, pair(p0, t * -r0)); break;
                case 14: acc = dsub(dadd(acc, pair(t, m0)), pair(p0, t * -r1)); break;
                case 16: acc = dsub(acc, pair(t * r0, p0)); break;
                case 18: acc = dadd(acc, pair(m0, t * -r2)); break;
                case 20: acc = dsub(dadd(acc, pair(t * r1, t * rr[j])), pair(p0, t * r0 * r0)); break;
                case 22: acc = dsub(acc, pair(t * r0 * r1, t * r0 * r2)); break;
                case 24: acc = dadd(acc, pair(t * r2, m0)); break;
                case 26: acc = dsub(dadd(acc, pair(t * -r0, m0)), pair(p0, t * r1 * r0)); break;
                case 28: acc = dsub(dadd(acc, pair(t * rr[j], m0)), pair(t * r1 * r1, t * r1 * r2)); break;
                case 30: acc = dadd(acc, pair(t * -r1, t * r0)); break;
                case 32: acc = dsub(acc, pair(p0, t * r2 * r0)); break;
                case 34: acc = dsub(dadd(acc, pair(m0, t * rr[j])), pair(t * r2 * r1, t * r2 * r2)); break;
                default: break;
                }
                acc = dadd(acc, dmul(splat((mm - t) * Jj[a]), Jp));
            }
            M[6 * a + k] = lane(acc, 0);
            M[6 * a + k + 1] = lane(acc, 1);
        }
    }
}

/* leg_mass_of compiled for each case that occurs, so that no case is tested per term. */
static void leg_mass(double *M, const double *J, double m_r, int legs, double mm, const double *kt, const double *rr,
                     const double *rho)
{
    if (m_r == 0.0 && legs) leg_mass_of(M, J, 0, m_r, 1, mm, kt, rr, rho);
    else if (legs) leg_mass_of(M, J, 1, m_r, 1, mm, kt, rr, rho);
    else if (m_r != 0.0) leg_mass_of(M, J, 1, m_r, 0, mm, kt, rr, rho);
}

/* The payload's centre of mass at c (in {B}, not 0) from o_P, the origin Kane's speeds
   follow: its acceleration is dv - c x dw + e with e = tr + alpha0 x c + w_abs x (w_abs x c)
   (alpha0 = eB + wB x w, the angular acceleration's part without dw), so its mass adds
   m e to the force rows, c x m e to the moment rows, and the couplings -m [c]x, m [c]x and
   m (c.c 1 - c c^T) to M; Ip is then about the centre of mass. Called only when c != 0, so
   that the c = 0 arithmetic is that of a centred payload, bit for bit. */
static void com_offset(double *M, double *h, double m, v3 c, v3 tr, v3 w_abs, v3 alpha0)
{
    v3 e = add(tr, add(cross(alpha0, c), cross(w_abs, cross(w_abs, c))));
    v3 ce = cross(c, e);
    const double C[9] = {0.0, -c.e[2], c.e[1], c.e[2], 0.0, -c.e[0], -c.e[1], c.e[0], 0.0};
    const double cc = dot(c, c);
    for (int i = 0; i < 3; i++) {
        h[i] = m * e.e[i];
        h[3 + i] += m * ce.e[i];
        for (int k = 0; k < 3; k++) {
            M[6 * i + 3 + k] -= m * C[3 * i + k];
            M[6 * (3 + i) + k] += m * C[3 * i + k];
            M[6 * (3 + i) + 3 + k] += m * ((i == k ? cc : 0.0) - c.e[i] * c.e[k]);
        }
    }
}

/* mb_hexapod_kane_ext, and for mb_hexapod_rhs_actuated: (pose_trig not NULL) the cos and
   sin of the last state's angles, so that it does not take them again; (frame not NULL)
   the base terms of every state, already computed; M_all, h_all and J_all may be NULL
   (not written). */
static void kane(const double *base_joints, const double *platform_joints, const double *data, int n_states,
                 const double *pose_all, const double *rate_all, const double *arg_all, const double *base_pose,
                 const double *base_rate, const double *base_acc, int base_mode, int legs, int twist_speeds,
                 int solve, double m_r, const double *wrench_all, double *M_all, double *h_all, double *J_all,
                 double *ldot, double *length, double *out_all, double *det, trig *pose_trig,
                 const base_frame *frame)
{
    const double m_p = data[0], g0 = data[10];
    const double Ip[3] = {data[1], data[2], data[3]};
    const double mf = data[4], lf = data[5], mm = data[6], lm = data[7], Ia = data[8], It = data[9];
    const double zero3[3] = {0.0, 0.0, 0.0};
    double R[9], A[36], b[6], x[6];
    for (int n = 0; n < n_states; n++) {
        const double *pose = pose_all + 6 * n, *rate = rate_all + 6 * n;
        double M[36], h[6], J[36];   /* built here, copied out at the end: no aliasing */
        double kt_j[6], rr_j[6], rho_j[18];   /* each leg's k_t, rho.rho and rho, for leg_mass */
        const trig tp = angles(pose + 3);
        if (pose_trig) *pose_trig = tp;
        rotation(&tp, R);
        v3 p = load(pose), v = load(rate);
        v3 w = twist_speeds ? load(rate + 3) : omega(&tp, rate + 3);

        /* base motion in {B} */
        const base_frame bf = frame ? *frame
                                    : base_terms(base_mode, g0, base_pose, base_rate, base_acc, n);
        const v3 g = bf.g, aB = bf.aB, wB = bf.wB, eB = bf.eB;

        /* platform */
        for (int i = 0; i < 36; i++) M[i] = 0.0;
        for (int i = 0; i < 3; i++) {
            M[7 * i] = m_p;
            for (int k = 0; k < 3; k++)
                M[6 * (3 + i) + 3 + k] = R[3 * i] * Ip[0] * R[3 * k] + R[3 * i + 1] * Ip[1] * R[3 * k + 1]
                                         + R[3 * i + 2] * Ip[2] * R[3 * k + 2];
        }
        v3 tr = transport(aB, g, eB, wB, p, v);
        v3 w_abs = add(w, wB);
        v3 Rt = mul_t(R, w_abs);
        v3 Iw_abs = mul(R, vec(Ip[0] * Rt.e[0], Ip[1] * Rt.e[1], Ip[2] * Rt.e[2]));
        Rt = mul_t(R, add(eB, cross(wB, w)));
        v3 torque = add(mul(R, vec(Ip[0] * Rt.e[0], Ip[1] * Rt.e[1], Ip[2] * Rt.e[2])), cross(w_abs, Iw_abs));
        for (int i = 0; i < 3; i++) {
            h[i] = m_p * tr.e[i];
            h[3 + i] = torque.e[i];
        }
        const v3 c_p = load(data + 11);   /* the payload's centre of mass in {P} */
        if (c_p.e[0] != 0.0 || c_p.e[1] != 0.0 || c_p.e[2] != 0.0)
            com_offset(M, h, m_p, mul(R, c_p), tr, w_abs, add(eB, cross(wB, w)));

        /* legs, two at a time (the lanes of d2); each leg's terms then enter M and h in
           leg order, as one leg at a time would add them */
        const w3 p2 = wsplat(p), v2 = wsplat(v), w2 = wsplat(w), g2 = wsplat(g), aB2 = wsplat(aB);
        const w3 eB2 = wsplat(eB), wB2 = wsplat(wB);
        const d2 one = splat(1.0), zero2 = splat(0.0), lf2 = splat(lf), mf2 = splat(mf), mm2 = splat(mm);
        const d2 It2 = splat(It), IaIt = splat(Ia - It);
        for (int j0 = 0; j0 < 6; j0 += 2) {
            w3 rho = wmul(R, wload(platform_joints, j0));
            w3 Bj = wload(base_joints, j0);
            w3 L = wvec(dsub(dadd(p2.x, rho.x), Bj.x), dsub(dadd(p2.y, rho.y), Bj.y), dsub(dadd(p2.z, rho.z), Bj.z));
            d2 l = dsqrt(wdot(L, L));
            w3 s = wlin(ddiv(one, l), L, zero2, L);
            w3 va = wadd(v2, wcross(w2, rho));
            d2 ld = wdot(s, va);
            w3 sd = wlin(ddiv(one, l), va, ddiv(dneg(ld), l), s);
            w3 rs = wcross(rho, s);
            w3 aa0 = wcross(w2, wcross(w2, rho));
            d2 ldd0 = dadd(wdot(s, aa0), dmul(l, wdot(sd, sd)));
            w3 f = s, rf = s;
            d2 kt = l, rr = l;
            if (legs) {
                w3 sdd0 = wlin(ddiv(one, l), aa0, ddiv(dneg(ldd0), l), s);
                sdd0 = wlin(one, sdd0, ddiv(dmul(splat(-2.0), ld), l), sd);
                d2 lr = dsub(l, splat(lm));
                w3 r_c = wlin(one, Bj, lf2, s);
                w3 r_m = wlin(one, Bj, lr, s);
                w3 v_c = wlin(lf2, sd, zero2, sd);
                w3 v_m = wlin(ld, s, lr, sd);
                w3 tr_c = wtransport(aB2, g2, eB2, wB2, r_c, v_c);
                w3 tr_m = wtransport(aB2, g2, eB2, wB2, r_m, v_m);
                w3 f_c = wlin(splat(mf * lf), sdd0, mf2, tr_c);
                w3 f_m = wadd(wlin(dmul(mm2, ldd0), s, dmul(splat(2.0 * mm), ld), sd), wlin(dmul(mm2, lr), sdd0, mm2, tr_m));
                w3 w_rel = wcross(s, sd);
                w3 w_leg = wadd(w_rel, wB2);
                w3 alpha = wadd(wcross(s, sdd0), wadd(eB2, wcross(wB2, w_rel)));
                w3 I_alpha = wlin(It2, alpha, dmul(IaIt, wdot(s, alpha)), s);
                w3 I_w = wlin(It2, w_leg, dmul(IaIt, wdot(s, w_leg)), s);
                w3 tau = wadd(I_alpha, wcross(w_leg, I_w));
                d2 fcs = wdot(s, f_c), fms = wdot(s, f_m);
                d2 lfl = ddiv(lf2, l), lrl = ddiv(lr, l);
                f = wadd(wlin(lfl, f_c, dmul(ddiv(dneg(lf2), l), fcs), s), wlin(lrl, f_m, dmul(fms, dsub(one, lrl)), s));
                f = wlin(one, f, ddiv(one, l), wcross(tau, s));
                rf = wcross(rho, f);
                kt = ddiv(dadd(dadd(splat(mf * lf * lf), dmul(dmul(mm2, lr), lr)), It2), dmul(l, l));
                rr = wdot(rho, rho);
            }
            for (int i = 0; i < 2; i++) {
                const int j = j0 + i;
                v3 si = pick(s, i), rsi = pick(rs, i), rhoi = pick(rho, i);
                ldot[6 * n + j] = lane(ld, i);
                length[6 * n + j] = lane(l, i);
                for (int k = 0; k < 3; k++) {
                    J[6 * j + k] = si.e[k];
                    J[6 * j + 3 + k] = rsi.e[k];
                }
                if (m_r != 0.0) {   /* reflected mass: T += m_r ld^2 / 2, ld = J_j u, ldd = J_j du + ldd0 */
                    double ldd_v = lane(ldd0, i);
                    for (int a = 0; a < 6; a++) h[a] += m_r * J[6 * j + a] * ldd_v;
                }
                if (!legs) continue;
                v3 fi = pick(f, i), rfi = pick(rf, i);
                for (int k = 0; k < 3; k++) {
                    h[k] += fi.e[k];
                    h[3 + k] += rfi.e[k];
                    rho_j[3 * j + k] = rhoi.e[k];
                }
                kt_j[j] = lane(kt, i);
                rr_j[j] = lane(rr, i);
            }
        }
        leg_mass(M, J, m_r, legs, mm, kt_j, rr_j, rho_j);

        if (wrench_all)   /* an external wrench W: M du + (h - W) = J^T F */
            for (int i = 0; i < 6; i++) h[i] -= wrench_all[6 * n + i];
        if (M_all) {
            for (int i = 0; i < 36; i++) {
                M_all[36 * n + i] = M[i];
                J_all[36 * n + i] = J[i];
            }
            for (int i = 0; i < 6; i++) h_all[6 * n + i] = h[i];
        }

        if (solve == MB_HEXAPOD_ID) {
            const double *arg = arg_all + 6 * n;
            double du[6];
            if (twist_speeds) {
                for (int k = 0; k < 6; k++) du[k] = arg[k];
            } else {
                v3 wd = omega_dot(&tp, rate + 3, arg + 3);
                du[0] = arg[0]; du[1] = arg[1]; du[2] = arg[2];
                du[3] = wd.e[0]; du[4] = wd.e[1]; du[5] = wd.e[2];
            }
            for (int i = 0; i < 6; i++) {
                double acc = h[i];
                for (int k = 0; k < 6; k++) {
                    acc += M[6 * i + k] * du[k];
                    A[6 * i + k] = J[6 * k + i];
                }
                b[i] = acc;
            }
            det[n] = mb_solve6(A, b, x);
            for (int k = 0; k < 6; k++) out_all[6 * n + k] = x[k];
            continue;
        }
        det[n] = mb_det6(J);
        if (solve == MB_HEXAPOD_FD) {
            const double *arg = arg_all + 6 * n;
            double *out = out_all + 6 * n;
            for (int i = 0; i < 6; i++) {
                double acc = -h[i];
                for (int k = 0; k < 6; k++) acc += J[6 * k + i] * arg[k];
                b[i] = acc;
            }
            mb_solve6(M, b, x);
            if (twist_speeds) {
                for (int k = 0; k < 6; k++) out[k] = x[k];
            } else {
                v3 wd0 = omega_dot(&tp, rate + 3, zero3);
                v3 rpy_acc = rpy_rate(&tp, vec(x[3] - wd0.e[0], x[4] - wd0.e[1], x[5] - wd0.e[2]));
                out[0] = x[0]; out[1] = x[1]; out[2] = x[2];
                out[3] = rpy_acc.e[0]; out[4] = rpy_acc.e[1]; out[5] = rpy_acc.e[2];
            }
        }
    }
}

void mb_hexapod_kane_ext(const double *base_joints, const double *platform_joints, const double *data,
                         int n_states, const double *pose_all, const double *rate_all, const double *arg_all,
                         const double *base_pose, const double *base_rate, const double *base_acc,
                         int base_mode, int legs, int twist_speeds, int solve, double m_r,
                         const double *wrench_all, double *M_all, double *h_all, double *J_all, double *ldot,
                         double *length, double *out_all, double *det)
{
    kane(base_joints, platform_joints, data, n_states, pose_all, rate_all, arg_all, base_pose, base_rate, base_acc,
         base_mode, legs, twist_speeds, solve, m_r, wrench_all, M_all, h_all, J_all, ldot, length, out_all, det, NULL,
         NULL);
}

void mb_hexapod_kane(const double *base_joints, const double *platform_joints, const double *data,
                     int n_states, const double *pose, const double *rate, const double *arg,
                     const double *base_pose, const double *base_rate, const double *base_acc,
                     int base_mode, int legs, int twist_speeds, int solve,
                     double *M, double *h, double *J, double *ldot, double *length, double *out, double *det)
{
    mb_hexapod_kane_ext(base_joints, platform_joints, data, n_states, pose, rate, arg, base_pose, base_rate,
                        base_acc, base_mode, legs, twist_speeds, solve, 0.0, NULL, M, h, J, ldot, length, out, det);
}

int mb_hexapod_kane_checked(const double *base_joints, const double *platform_joints, const double *data,
                            int n, const double *pose, const double *rate, const double *arg,
                            const double *base_pose, const double *base_rate, const double *base_acc,
                            int base_mode, int legs, int twist_speeds, int solve, double *work)
{
    const double *states[6] = {pose, rate, arg, base_pose, base_rate, base_acc};
    const size_t m = (size_t)n;
    int bad = 0;
    for (int k = 0; k < 6; k++) {
        if (!states[k]) continue;
        for (size_t i = 0; i < 6 * m; i++)
            if (!isfinite(states[k][i])) {
                bad |= 1 << k;
                break;
            }
    }
    if (!bad)
        mb_hexapod_kane(base_joints, platform_joints, data, n, pose, rate, arg, base_pose, base_rate, base_acc,
                        base_mode, legs, twist_speeds, solve, work, work + 36 * m, work + 42 * m, work + 78 * m,
                        work + 84 * m, work + 90 * m, work + 96 * m);
    return bad;
}

/* Leg rates [m/s] of x = [pose, twist]: mb_hexapod_leg_kinematics' (defined below). */
static void leg_rates(const double *bj, const double *pj, const double *x, double *ld)
{
    double outputs[18];
    mb_hexapod_leg_kinematics(bj, pj, x, outputs);
    for (int j = 0; j < 6; j++) ld[j] = outputs[6 + j];
}

static inline double clamp(double f, double limit)
{
    return limit > 0.0 ? (f > limit ? limit : (f < -limit ? -limit : f)) : f;
}

/* The force each actuator delivers to its leg: the motor's (the lag state x[12 + j]
   with a bandwidth, else the limited command) less the screw's friction at the leg
   rates ld (read only with friction on). */
static void delivered(const double *act, const double *x, const double *command, const double *ld, double *force)
{
    double fc = act[MB_ACT_COULOMB], c = act[MB_ACT_VISCOUS], vs = act[MB_ACT_FRICTION_VELOCITY];
    int lag = act[MB_ACT_BANDWIDTH] > 0.0, friction = fc != 0.0 || c != 0.0;
    for (int j = 0; j < 6; j++) {
        double f = lag ? x[12 + j] : clamp(command[j], act[MB_ACT_FORCE_LIMIT]);
        force[j] = friction ? f - (fc * tanh(ld[j] / vs) + c * ld[j]) : f;
    }
}

/* The base terms of the last time an RK4 step asked for: its two middle stages share a
   time, hence the same base and the same numbers. */
typedef struct { int valid; double t; base_frame f; } base_memo;

/* mb_hexapod_rhs_actuated, taking the base terms from memo (not NULL) when it holds t's. */
static double rhs(const double *bj, const double *pj, const double *data, const double *act, const double *x,
                  const double *command, const double *wrench, const double *base0, double t0, double t,
                  int base_mode, int legs, double *dx, double *force, base_memo *memo)
{
    double base[18], ldot[6], length[6], out[6], det, f[6], ld[6];
    double tau = t - t0;
    const double *forces = command;
    if (act) {
        int friction = act[MB_ACT_COULOMB] != 0.0 || act[MB_ACT_VISCOUS] != 0.0;
        if (friction) leg_rates(bj, pj, x, ld);
        if (friction || act[MB_ACT_BANDWIDTH] > 0.0 || act[MB_ACT_FORCE_LIMIT] > 0.0) {
            delivered(act, x, command, ld, f);
            forces = f;
        }   /* else delivered would copy the command */
        if (act[MB_ACT_BANDWIDTH] > 0.0) {   /* dF/dt = 2 pi f_bw (F_cmd - F) */
            double rate = 2.0 * M_PI * act[MB_ACT_BANDWIDTH];
            for (int j = 0; j < 6; j++) dx[12 + j] = rate * (clamp(command[j], act[MB_ACT_FORCE_LIMIT]) - x[12 + j]);
        }
    }
    if (force)
        for (int j = 0; j < 6; j++) force[j] = forces[j];
    base_frame bf;
    if (memo && memo->valid && memo->t == t) {
        bf = memo->f;
    } else {
        if (base_mode == MB_HEXAPOD_BASE_NONE) {
            bf = base_terms(base_mode, data[10], NULL, NULL, NULL, 0);
        } else {
            for (int k = 0; k < 6; k++) {
                base[k] = base0[k] + tau * base0[6 + k] + 0.5 * tau * tau * base0[12 + k];
                base[6 + k] = base0[6 + k] + tau * base0[12 + k];
                base[12 + k] = base0[12 + k];
            }
            bf = base_terms(base_mode, data[10], base, base + 6, base + 12, 0);
        }
        if (memo) {
            memo->valid = 1;
            memo->t = t;
            memo->f = bf;
        }
    }
    trig tx;
    kane(bj, pj, data, 1, x, x + 6, forces, NULL, NULL, NULL, base_mode, legs, 1, MB_HEXAPOD_FD,
         act ? act[MB_ACT_REFLECTED_MASS] : 0.0, wrench, NULL, NULL, NULL, ldot, length, out, &det, &tx, &bf);
    v3 rr = rpy_rate(&tx, load(x + 9));
    for (int k = 0; k < 3; k++) {
        dx[k] = x[6 + k];
        dx[3 + k] = rr.e[k];
    }
    for (int k = 0; k < 6; k++) dx[6 + k] = out[k];
    return fabs(det);
}

double mb_hexapod_rhs_actuated(const double *bj, const double *pj, const double *data, const double *act,
                               const double *x, const double *command, const double *wrench, const double *base0,
                               double t0, double t, int base_mode, int legs, double *dx, double *force)
{
    return rhs(bj, pj, data, act, x, command, wrench, base0, t0, t, base_mode, legs, dx, force, NULL);
}

double mb_hexapod_rhs(const double *bj, const double *pj, const double *data, const double *x,
                      const double *forces, const double *base0, double t0, double t, int base_mode,
                      int legs, double *dx)
{
    return mb_hexapod_rhs_actuated(bj, pj, data, NULL, x, forces, NULL, base0, t0, t, base_mode, legs, dx, NULL);
}

void mb_hexapod_leg_kinematics(const double *bj, const double *pj, const double *x, double *outputs)
{
    double R[9];
    const trig t = angles(x + 3);
    rotation(&t, R);
    v3 v = load(x + 6), w = load(x + 9);
    for (int j = 0; j < 6; j++) {
        v3 rho = mul(R, load(pj + 3 * j));
        v3 L = vec(x[0] + rho.e[0] - bj[3 * j], x[1] + rho.e[1] - bj[3 * j + 1], x[2] + rho.e[2] - bj[3 * j + 2]);
        double l = sqrt(dot(L, L));
        outputs[j] = l;
        outputs[6 + j] = dot(L, add(v, cross(w, rho))) / l;
    }
    v3 rr = rpy_rate(&t, w);
    for (int k = 0; k < 3; k++) {
        outputs[12 + k] = v.e[k];
        outputs[15 + k] = rr.e[k];
    }
}

/* advance_fixed and advance_actuated: act NULL (ideal actuators, no wrench, 4 input rows,
   3 output rows) or the actuator data (5 input rows with the wrench, 4 output rows). */
static int advance(int rk4, int substeps, const double *bj, const double *pj, const double *data,
                   const double *act, double *x, const double *inputs, double t0, double h, int base_mode,
                   int legs, const double *bounds, double *outputs, double *det_min)
{
    double k1[18], k2[18], k3[18], k4[18], xs[18];
    int nx = act && act[MB_ACT_BANDWIDTH] > 0.0 ? 18 : 12, ninputs = act ? 30 : 24;
    *det_min = 0.0;
    for (int k = 0; k < ninputs; k++)
        if (!isfinite(inputs[k])) return MB_HEXAPOD_BAD_INPUT;
    const double *forces = inputs, *base0 = inputs + 6, *wrench = NULL;
    if (act)
        for (int k = 24; k < 30; k++)
            if (inputs[k] != 0.0) wrench = inputs + 24;
    double dt = h / substeps, dmin = INFINITY, d;
    base_memo memo;
    memo.valid = 0;
    for (int n = 0; n < substeps; n++) {
        double t = t0 + n * dt;
        d = rhs(bj, pj, data, act, x, forces, wrench, base0, t0, t, base_mode, legs, k1, NULL, &memo);
        if (d < dmin) dmin = d;
        if (!rk4) {
            for (int k = 0; k < nx; k++) x[k] += dt * k1[k];
            continue;
        }
        for (int k = 0; k < nx; k++) xs[k] = x[k] + 0.5 * dt * k1[k];
        d = rhs(bj, pj, data, act, xs, forces, wrench, base0, t0, t + 0.5 * dt, base_mode, legs, k2, NULL, &memo);
        if (d < dmin) dmin = d;
        for (int k = 0; k < nx; k++) xs[k] = x[k] + 0.5 * dt * k2[k];
        d = rhs(bj, pj, data, act, xs, forces, wrench, base0, t0, t + 0.5 * dt, base_mode, legs, k3, NULL, &memo);
        if (d < dmin) dmin = d;
        for (int k = 0; k < nx; k++) xs[k] = x[k] + dt * k3[k];
        d = rhs(bj, pj, data, act, xs, forces, wrench, base0, t0, t + dt, base_mode, legs, k4, NULL, &memo);
        if (d < dmin) dmin = d;
        for (int k = 0; k < nx; k++) x[k] += dt / 6.0 * (k1[k] + 2.0 * k2[k] + 2.0 * k3[k] + k4[k]);
    }
    *det_min = dmin;
    for (int k = 0; k < nx; k++)
        if (!isfinite(x[k]) || (k < 3 && fabs(x[k]) > 100.0)) return MB_HEXAPOD_DIVERGED;
    mb_hexapod_leg_kinematics(bj, pj, x, outputs);
    if (act) delivered(act, x, forces, outputs + 6, outputs + 18);
    int status = MB_HEXAPOD_OK;
    for (int j = 0; j < 6; j++)
        if (outputs[j] < bounds[j] || outputs[j] > bounds[6 + j]) status = MB_HEXAPOD_STROKE;
    return status;
}

int mb_hexapod_advance_fixed(int rk4, int substeps, const double *bj, const double *pj,
                             const double *data, double *x, const double *inputs, double t0, double h,
                             int base_mode, int legs, const double *bounds, double *outputs,
                             double *det_min)
{
    return advance(rk4, substeps, bj, pj, data, NULL, x, inputs, t0, h, base_mode, legs, bounds, outputs, det_min);
}

int mb_hexapod_advance_actuated(int rk4, int substeps, const double *bj, const double *pj, const double *data,
                                const double *act, double *x, const double *inputs, double t0, double h,
                                int base_mode, int legs, const double *bounds, double *outputs, double *det_min)
{
    return advance(rk4, substeps, bj, pj, data, act, x, inputs, t0, h, base_mode, legs, bounds, outputs, det_min);
}

/* The pose rates [v, RPY rates] of x = [pose, twist]: no dynamics, the kinematics alone. */
static void pose_rate(const double *x, double *rate)
{
    const trig t = angles(x + 3);
    v3 rr = rpy_rate(&t, load(x + 9));
    for (int k = 0; k < 3; k++) {
        rate[k] = x[6 + k];
        rate[3 + k] = rr.e[k];
    }
}

/* The motor forces of the lag at tau after the step's start: exact, the command held. */
static void lag_forces(const double *act, const double *command, const double *f0, double tau, double *f)
{
    double decay = exp(-2.0 * M_PI * act[MB_ACT_BANDWIDTH] * tau);
    for (int j = 0; j < 6; j++) {
        double target = clamp(command[j], act[MB_ACT_FORCE_LIMIT]);
        f[j] = target + (f0[j] - target) * decay;
    }
}

int mb_hexapod_advance_controlled(double tol, double max_step, int max_substeps, const double *bj,
                                  const double *pj, const double *data, const double *act, double *x,
                                  const double *inputs, double t0, double h, int base_mode, int legs,
                                  const double *bounds, double *outputs, double *det_min, int *counts)
{
    double k1[18], k2[18], k3[18], k4[18], xs[18], xn[12], x0[18], f0[6], rate[6];
    int lag = act[MB_ACT_BANDWIDTH] > 0.0;
    *det_min = 0.0;
    counts[0] = counts[1] = 0;
    for (int k = 0; k < 30; k++)
        if (!isfinite(inputs[k])) return MB_HEXAPOD_BAD_INPUT;
    const double *forces = inputs, *base0 = inputs + 6, *wrench = NULL;
    for (int k = 24; k < 30; k++)
        if (inputs[k] != 0.0) wrench = inputs + 24;
    for (int k = 0; k < (lag ? 18 : 12); k++) x0[k] = x[k];
    for (int j = 0; j < 6; j++) f0[j] = lag ? x[12 + j] : 0.0;
    double tau = 0.0, dt = h < max_step ? h : max_step, dmin = INFINITY, d1 = INFINITY;
    int have_k1 = 0;   /* k1 holds the rates at (tau, x): a rejected substep's, for its retry */
    base_memo memo;
    memo.valid = 0;
    while (tau < h) {
        if (counts[0] + counts[1] >= max_substeps) {   /* x as it came */
            for (int k = 0; k < (lag ? 18 : 12); k++) x[k] = x0[k];
            return MB_HEXAPOD_WORK;
        }
        int last = tau + dt >= h * (1.0 - 1e-12);
        if (last) dt = h - tau;
        double t = t0 + tau, d, dstep = INFINITY;
        /* classic RK4 over [tau, tau + dt], the lag's forces exact at each stage's time */
        if (lag) lag_forces(act, forces, f0, tau, x + 12);
        if (!have_k1)
            d1 = rhs(bj, pj, data, act, x, forces, wrench, base0, t0, t, base_mode, legs, k1, NULL, &memo);
        dstep = d1 < dstep ? d1 : dstep;
        for (int k = 0; k < 12; k++) xs[k] = x[k] + 0.5 * dt * k1[k];
        if (lag) lag_forces(act, forces, f0, tau + 0.5 * dt, xs + 12);
        d = rhs(bj, pj, data, act, xs, forces, wrench, base0, t0, t + 0.5 * dt, base_mode, legs, k2, NULL, &memo);
        dstep = d < dstep ? d : dstep;
        for (int k = 0; k < 12; k++) xs[k] = x[k] + 0.5 * dt * k2[k];
        d = rhs(bj, pj, data, act, xs, forces, wrench, base0, t0, t + 0.5 * dt, base_mode, legs, k3, NULL, &memo);
        dstep = d < dstep ? d : dstep;
        for (int k = 0; k < 12; k++) xs[k] = x[k] + dt * k3[k];
        if (lag) lag_forces(act, forces, f0, tau + dt, xs + 12);
        d = rhs(bj, pj, data, act, xs, forces, wrench, base0, t0, t + dt, base_mode, legs, k4, NULL, &memo);
        dstep = d < dstep ? d : dstep;
        for (int k = 0; k < 12; k++) xn[k] = x[k] + dt / 6.0 * (k1[k] + 2.0 * k2[k] + 2.0 * k3[k] + k4[k]);
        /* the embedded third-order pose, x + dt/6 (k1 + 2 k2 + 2 k3 + k5) with k5 the rate at
           the new state: its pose part is kinematic, so the estimate costs no dynamics */
        pose_rate(xn, rate);
        double err = 0.0;
        for (int k = 0; k < 6; k++) {
            double e = fabs(dt / 6.0 * (k4[k] - rate[k])) / tol;
            err = e > err || isnan(e) ? e : err;
        }
        int finite = 1;
        for (int k = 0; k < 12; k++) finite &= isfinite(xn[k]);
        if (err <= 1.0 && finite) {
            for (int k = 0; k < 12; k++) x[k] = xn[k];
            tau = last ? h : tau + dt;
            dmin = dstep < dmin ? dstep : dmin;
            counts[0]++;
            have_k1 = 0;
        } else {
            counts[1]++;
            have_k1 = 1;   /* x and tau stand: the retry starts from the same rates */
        }
        /* the next substep: the usual controller for a local error of order 4, within [0.2, 4] x */
        double grow = err > 0.0 ? 0.9 * pow(err, -0.25) : 4.0;
        grow = !(grow >= 0.2) ? 0.2 : (grow > 4.0 ? 4.0 : grow);
        dt *= grow;
        if (dt > max_step) dt = max_step;
    }
    if (lag) lag_forces(act, forces, f0, h, x + 12);
    *det_min = dmin;
    for (int k = 0; k < 12; k++)
        if (!isfinite(x[k]) || (k < 3 && fabs(x[k]) > 100.0)) return MB_HEXAPOD_DIVERGED;
    mb_hexapod_leg_kinematics(bj, pj, x, outputs);
    delivered(act, x, forces, outputs + 6, outputs + 18);
    int status = MB_HEXAPOD_OK;
    for (int j = 0; j < 6; j++)
        if (outputs[j] < bounds[j] || outputs[j] > bounds[6 + j]) status = MB_HEXAPOD_STROKE;
    return status;
}

double mb_hexapod_inverse_dynamics(const double *base_joints, const double *platform_joints,
                                   const double *data, const double *pose, const double *pose_rate,
                                   const double *pose_acc, const double *base_pose,
                                   const double *base_rate, const double *base_acc, int base_mode,
                                   int legs, double *forces, double *length, double *ldot)
{
    double M[36], h[6], J[36], det;
    mb_hexapod_kane(base_joints, platform_joints, data, 1, pose, pose_rate, pose_acc, base_pose, base_rate,
                    base_acc, base_mode, legs, 0, MB_HEXAPOD_ID, M, h, J, ldot, length, forces, &det);
    return det;
}

double mb_hexapod_state_inverse_dynamics(const struct mb_hexapod_state_id *s)
{
    return mb_hexapod_inverse_dynamics(s->base_joints, s->platform_joints, s->data, s->state[0], s->state[1],
                                       s->state[2], s->state[3], s->state[4], s->state[5], s->base_mode, s->legs,
                                       s->forces, s->length, s->ldot);
}
