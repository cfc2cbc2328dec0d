/* Single-state kernel of the 3T mechanism (mechanism3t.h says what and in which units).

   The formulas are those of plant/mechanism3t/model.py (_forward, _limb3_motion, _two_link,
   _along, _bodies, dynamics_terms), term by term and in the same order of operations,
   with rho_ddot = 0 for the bias and unit slider rates for the velocity Jacobians, as
   dynamics_terms does. Scalar code on the stack: no allocation. */
#include <math.h>
#include "linalg.h"
#include "mechanism3t.h"

#define SINGULAR_TOL 1e-7   /* plant.mechanism3t.model.SINGULAR_TOL */

/* Rate-independent quantities of one configuration (_geometry). */
typedef struct {
    double sin, cos, w, v, cp, sp;
    double ca1, sa1, cb1, sb1, s1;
    double ca2, sa2, cb2, sb2, s2;
} geometry;

/* Velocities and accelerations of the centres of mass and rates of the swing angles. */
typedef struct {
    double vel[MB_M3T_NBODY][3], acc[MB_M3T_NBODY][3];
    double rate[MB_M3T_NTURN], ang_acc[MB_M3T_NTURN];
} motion;

static double clamp1(double c)
{
    double lo = -1.0 > c ? -1.0 : c;   /* Python max(c, -1.0), min(., 1.0) */
    return 1.0 < lo ? 1.0 : lo;
}

static double sq(double x) { return x * x; }

static int finite3(const double *x)
{
    return isfinite(x[0]) && isfinite(x[1]) && isfinite(x[2]);
}

static double eq8_disc(double u, double w, double l_in, double l_out)
{
    double n1 = -2 * l_in * w, n2 = -2 * l_in * u;
    double n3 = sq(l_out) - sq(l_in) - sq(u) - sq(w);
    return sq(n1) + sq(n2) - sq(n3);
}

/* theta and O' z of assembly mode `mode` (_forward); returns the status. */
static int position(const double *pa, double x_A2, double y_A1, double y_A3, int mode,
                    double *theta, double *z)
{
    double a = pa[0], b = pa[1], d = pa[2], e = pa[3], l1 = pa[4], l2 = pa[5], l3 = pa[6];
    double l4 = pa[7], l5 = pa[8], l6 = pa[9];
    double root2 = sq(l6) - sq(y_A1 + d - y_A3);
    double cos_ = (e - a - x_A2 + (double)mode * sqrt(0.0 > root2 ? 0.0 : root2)) / l4;
    *theta = acos(clamp1(cos_));
    *z = l1 + l5 + l4 * sin(*theta);
    if (root2 < 0) return MB_M3T_UNREACH_D3E3;
    if (fabs(cos_) > 1) return MB_M3T_UNREACH_ARCCOS;
    if (eq8_disc(x_A2 - a, *z - l1, l2, l3) < 0) return MB_M3T_UNREACH_LIMB1;
    if (eq8_disc(y_A1 + d + d - b, *z - l1, l2, l3) < 0) return MB_M3T_UNREACH_LIMB2;
    return MB_M3T_OK;
}

/* cos/sin of alpha and beta and sin(beta - alpha) of a planar 2R limb reaching (u, w). */
static void knee(double u, double w, double l_in, double l_out, double sign,
                 double *ca, double *sa, double *cb, double *sb, double *s)
{
    double r = hypot(u, w);
    double c = (sq(l_in) + sq(r) - sq(l_out)) / (2 * l_in * r);
    double alpha = atan2(w, u) + sign * acos(clamp1(c));
    double beta = atan2(w - l_in * sin(alpha), u - l_in * cos(alpha));
    *s = sin(beta - alpha);
    *ca = cos(alpha); *sa = sin(alpha); *cb = cos(beta); *sb = sin(beta);
}

/* alpha_d, alpha_dd, beta_d, beta_dd of _two_link. */
static void knee_rates(double u_d, double u_dd, double w_d, double w_dd, double ca, double sa,
                       double cb, double sb, double s, double l_in, double l_out, double *out)
{
    double a_d = (u_d * cb + w_d * sb) / (l_in * s);
    double b_d = -(u_d * ca + w_d * sa) / (l_out * s);
    double q_u = u_dd + l_in * sq(a_d) * ca + l_out * sq(b_d) * cb;
    double q_w = w_dd + l_in * sq(a_d) * sa + l_out * sq(b_d) * sb;
    out[0] = a_d;
    out[1] = (q_u * cb + q_w * sb) / (l_in * s);
    out[2] = b_d;
    out[3] = -(q_u * ca + q_w * sa) / (l_out * s);
}

/* In-plane (u, w) velocity and acceleration of length (cos q, sin q) (_along):
   out = (vu, vw, au, aw). */
static void arm(double q_d, double q_dd, double cq, double sq_, double length, double *out)
{
    out[0] = -length * q_d * sq_;
    out[1] = length * q_d * cq;
    out[2] = length * (-q_dd * sq_ - sq(q_d) * cq);
    out[3] = length * (q_dd * cq - sq(q_d) * sq_);
}

/* O' z and the geometry of one configuration (rho finite); returns the status. */
static int geometry_of(const double *pa, const double *rho, int mode, double *z, geometry *g)
{
    double a = pa[0], b = pa[1], d = pa[2], e = pa[3], l1 = pa[4], l2 = pa[5], l3 = pa[6];
    double l4 = pa[7], l6 = pa[9];
    double x = rho[0], y = rho[1] + d, theta;
    int status = position(pa, rho[0], rho[1], rho[2], mode, &theta, z);
    if (status != MB_M3T_OK) return status;
    g->sin = sin(theta);
    g->cos = cos(theta);
    g->w = x - e + a + l4 * g->cos;
    g->v = y - rho[2];
    if (fabs(g->sin) < SINGULAR_TOL) return MB_M3T_SING_SIN;
    if (fabs(g->w) / l6 < SINGULAR_TOL) return MB_M3T_SING_W;
    knee(x - a, *z - l1, l2, l3, pa[11], &g->ca1, &g->sa1, &g->cb1, &g->sb1, &g->s1);
    if (fabs(g->s1) < SINGULAR_TOL) return MB_M3T_SING_LIMB1;
    knee(y + d - b, *z - l1, l2, l3, pa[12], &g->ca2, &g->sa2, &g->cb2, &g->sb2, &g->s2);
    if (fabs(g->s2) < SINGULAR_TOL) return MB_M3T_SING_LIMB2;
    double psi = atan2(g->v, g->w);
    g->cp = cos(psi);
    g->sp = sin(psi);
    return MB_M3T_OK;
}

static void set3(double *row, double x, double y, double z) { row[0] = x; row[1] = y; row[2] = z; }

/* Velocity and acceleration of every centre of mass and rate and acceleration of every swing
   angle for slider rates (xd, y1d, y3d) and accelerations (xdd, y1dd, y3dd) (_motion). */
static void motion_of(const double *pa, const geometry *g, double xd, double y1d, double y3d,
                      double xdd, double y1dd, double y3dd, motion *m)
{
    double l2 = pa[5], l3 = pa[6], l4 = pa[7], l6 = pa[9];
    double sin_ = g->sin, cos_ = g->cos, w = g->w, v = g->v;
    /* limb III and O' (_limb3_motion) */
    double v_d = y1d - y3d, v_dd = y1dd - y3dd;
    double den = w * l4 * sin_;
    double th_d = (w * xd + v * v_d) / den;
    double w_d = xd - l4 * sin_ * th_d;
    double th_dd = (sq(w_d) + sq(v_d) + v * v_dd + w * (xdd - l4 * cos_ * sq(th_d))) / den;
    double w_dd = xdd - l4 * cos_ * sq(th_d) - l4 * sin_ * th_dd;
    double zd = l4 * cos_ * th_d, zdd = l4 * (cos_ * th_dd - sin_ * sq(th_d));
    double psi_d = (w * v_d - v * w_d) / sq(l6), psi_dd = (w * v_dd - v * w_dd) / sq(l6);
    double k1[4], k2[4], r[4], c[4];
    knee_rates(xd, xdd, zd, zdd, g->ca1, g->sa1, g->cb1, g->sb1, g->s1, l2, l3, k1);
    knee_rates(y1d, y1dd, zd, zdd, g->ca2, g->sa2, g->cb2, g->sb2, g->s2, l2, l3, k2);
    set3(m->vel[0], xd, 0.0, 0.0);                       /* slider 2 (x_A2) */
    set3(m->acc[0], xdd, 0.0, 0.0);
    set3(m->vel[1], 0.0, y1d, 0.0);                      /* slider 1 (y_A1) */
    set3(m->acc[1], 0.0, y1dd, 0.0);
    set3(m->vel[2], 0.0, y3d, 0.0);                      /* slider 3 (y_A3) */
    set3(m->acc[2], 0.0, y3dd, 0.0);
    /* limb I in the (x, z) plane, riding on slider 1 */
    arm(k1[0], k1[1], g->ca1, g->sa1, 0.5 * l2, r);
    set3(m->vel[3], r[0], y1d, r[1]);
    set3(m->acc[3], r[2], y1dd, r[3]);
    arm(k1[0], k1[1], g->ca1, g->sa1, l2, c);
    arm(k1[2], k1[3], g->cb1, g->sb1, 0.5 * l3, r);
    set3(m->vel[4], c[0] + r[0], y1d, c[1] + r[1]);
    set3(m->acc[4], c[2] + r[2], y1dd, c[3] + r[3]);
    /* limb II in the (y, z) plane, riding on slider 2 */
    arm(k2[0], k2[1], g->ca2, g->sa2, 0.5 * l2, r);
    set3(m->vel[5], xd, r[0], r[1]);
    set3(m->acc[5], xdd, r[2], r[3]);
    arm(k2[0], k2[1], g->ca2, g->sa2, l2, c);
    arm(k2[2], k2[3], g->cb2, g->sb2, 0.5 * l3, r);
    set3(m->vel[6], xd, c[0] + r[0], c[1] + r[1]);
    set3(m->acc[6], xdd, c[2] + r[2], c[3] + r[3]);
    /* limb III in the (-x, z) plane, riding on slider 3; C3D3 translates with C3 */
    arm(th_d, th_dd, cos_, sin_, 0.5 * l4, r);
    set3(m->vel[7], -r[0], y3d, r[1]);
    set3(m->acc[7], -r[2], y3dd, r[3]);
    arm(th_d, th_dd, cos_, sin_, l4, c);
    set3(m->vel[8], -c[0], y3d, c[1]);
    set3(m->acc[8], -c[2], y3dd, c[3]);
    /* D3E3 in the (x, y) plane from D3 */
    arm(psi_d, psi_dd, g->cp, g->sp, 0.5 * l6, r);
    set3(m->vel[9], -c[0] + r[0], y3d + r[1], c[1]);
    set3(m->acc[9], -c[2] + r[2], y3dd + r[3], c[3]);
    set3(m->vel[10], xd, y1d, zd);
    set3(m->acc[10], xdd, y1dd, zdd);
    m->rate[0] = k1[0]; m->rate[1] = k1[2]; m->rate[2] = k2[0];
    m->rate[3] = k2[2]; m->rate[4] = th_d; m->rate[5] = psi_d;
    m->ang_acc[0] = k1[1]; m->ang_acc[1] = k1[3]; m->ang_acc[2] = k2[1];
    m->ang_acc[3] = k2[3]; m->ang_acc[4] = th_dd; m->ang_acc[5] = psi_dd;
}

int mb_m3t_position(const double *pa, const double *rho, int mode, double *p)
{
    if (mode != 1 && mode != -1) return MB_M3T_BAD_MODE;
    if (!finite3(rho)) return MB_M3T_BAD_RHO;
    double theta, z;
    int status = position(pa, rho[0], rho[1], rho[2], mode, &theta, &z);
    p[0] = rho[0]; p[1] = rho[1] + pa[2]; p[2] = z;
    return status;
}

int mb_m3t_terms(const double *pa, const double *rho, const double *rho_dot, int mode,
                 double *M, double *bias, double *p)
{
    if (mode != 1 && mode != -1) return MB_M3T_BAD_MODE;
    if (!finite3(rho)) return MB_M3T_BAD_RHO;
    if (!finite3(rho_dot)) return MB_M3T_BAD_RHO_DOT;
    geometry geo;
    double z;
    int status = geometry_of(pa, rho, mode, &z, &geo);
    if (status != MB_M3T_OK) return status;
    p[0] = rho[0]; p[1] = rho[1] + pa[2]; p[2] = z;
    motion mo[4];   /* [0]: the state's rates, no acceleration; [1..3]: unit slider rates */
    motion_of(pa, &geo, rho_dot[0], rho_dot[1], rho_dot[2], 0.0, 0.0, 0.0, &mo[0]);
    for (int j = 0; j < 3; j++)
        motion_of(pa, &geo, j == 0 ? 1.0 : 0.0, j == 1 ? 1.0 : 0.0, j == 2 ? 1.0 : 0.0,
                  0.0, 0.0, 0.0, &mo[j + 1]);
    double g = pa[10];
    for (int i = 0; i < 3; i++) {
        bias[i] = 0.0;
        for (int j = 0; j < 3; j++) M[3 * i + j] = 0.0;
    }
    for (int k = 0; k < MB_M3T_NBODY; k++) {
        double m = pa[MB_M3T_M0 + k];
        double a0 = mo[0].acc[k][0], a1 = mo[0].acc[k][1], a2 = mo[0].acc[k][2] + g;
        for (int i = 0; i < 3; i++) {
            const double *ji = mo[i + 1].vel[k];
            bias[i] += m * (a0 * ji[0] + a1 * ji[1] + a2 * ji[2]);
            for (int j = 0; j < 3; j++) {
                const double *jj = mo[j + 1].vel[k];
                M[3 * i + j] += m * (ji[0] * jj[0] + ji[1] * jj[1] + ji[2] * jj[2]);
            }
        }
    }
    for (int k = 0; k < MB_M3T_NTURN; k++) {
        double inertia = pa[MB_M3T_I0 + k];
        for (int i = 0; i < 3; i++) {
            bias[i] += inertia * mo[0].ang_acc[k] * mo[i + 1].rate[k];
            for (int j = 0; j < 3; j++)
                M[3 * i + j] += inertia * mo[i + 1].rate[k] * mo[j + 1].rate[k];
        }
    }
    return MB_M3T_OK;
}

int mb_m3t_slider_forces(const double *pa, const double *rho, const double *rho_dot,
                         const double *rho_ddot, int mode, double *forces)
{
    if (!finite3(rho)) return MB_M3T_BAD_RHO;
    if (!finite3(rho_dot)) return MB_M3T_BAD_RHO_DOT;
    if (!finite3(rho_ddot)) return MB_M3T_BAD_RHO_DDOT;
    double M[9], bias[3], p[3];
    int status = mb_m3t_terms(pa, rho, rho_dot, mode, M, bias, p);
    if (status != MB_M3T_OK) return status;
    for (int i = 0; i < 3; i++)
        forces[i] = M[3 * i] * rho_ddot[0] + M[3 * i + 1] * rho_ddot[1] + M[3 * i + 2] * rho_ddot[2] + bias[i];
    return MB_M3T_OK;
}

int mb_m3t_forward_dynamics(const double *pa, const double *rho, const double *rho_dot,
                            const double *forces, int mode, double *rho_ddot)
{
    if (!finite3(forces)) return MB_M3T_BAD_FORCE;
    double M[9], bias[3], p[3];
    int status = mb_m3t_terms(pa, rho, rho_dot, mode, M, bias, p);
    if (status != MB_M3T_OK) return status;
    for (int i = 0; i < 3; i++) bias[i] = forces[i] - bias[i];
    if (mb_solve(3, M, bias, rho_ddot) == 0.0) return MB_M3T_SING_MASS;
    return MB_M3T_OK;
}

int mb_m3t_rhs(const double *pa, const double *x, const double *forces, int mode, double *xdot)
{
    xdot[0] = x[3]; xdot[1] = x[4]; xdot[2] = x[5];
    return mb_m3t_forward_dynamics(pa, x, x + 3, forces, mode, xdot + 3);
}

int mb_m3t_advance_fixed(const double *pa, double *x, const double *forces, int mode,
                         int rk4, int substeps, double dt)
{
    double k[4][6], xs[6];
    double half = 0.5 * dt, sixth = dt / 6.0;
    const double stage[3] = {half, half, dt};
    for (int n = 0; n < substeps; n++) {
        int status = mb_m3t_rhs(pa, x, forces, mode, k[0]);
        if (status != MB_M3T_OK) return status;
        if (!rk4) {
            for (int i = 0; i < 6; i++) x[i] = x[i] + dt * k[0][i];
            continue;
        }
        for (int s = 0; s < 3; s++) {
            for (int i = 0; i < 6; i++) xs[i] = x[i] + stage[s] * k[s][i];
            status = mb_m3t_rhs(pa, xs, forces, mode, k[s + 1]);
            if (status != MB_M3T_OK) return status;
        }
        for (int i = 0; i < 6; i++)
            x[i] = x[i] + sixth * (k[0][i] + 2.0 * k[1][i] + 2.0 * k[2][i] + k[3][i]);
    }
    return MB_M3T_OK;
}

int mb_m3t_plant_step(const double *pa, double *x, const double *forces, int mode,
                      int rk4, int substeps, double dt, double *p)
{
    int status = mb_m3t_advance_fixed(pa, x, forces, mode, rk4, substeps, dt);
    if (status != MB_M3T_OK) return status;
    for (int i = 0; i < 6; i++)
        if (!isfinite(x[i])) return MB_M3T_DIVERGED;
    return mb_m3t_position(pa, x, mode, p);
}

void mb_m3t_paper_motion(double t, const double *centre, double amplitude, double omega,
                         double *rho, double *rho_dot, double *rho_ddot)
{
    double s = sin(omega * t), c = cos(omega * t);
    for (int i = 0; i < 3; i++) {
        rho[i] = centre[i] + amplitude * s;
        rho_dot[i] = amplitude * omega * c;
        rho_ddot[i] = -amplitude * sq(omega) * s;
    }
}

int mb_m3t_reference_forces(const double *pa, double t, const double *centre, double amplitude,
                            double omega, int mode, double *ref, double *ref_rate,
                            double *ref_acc, double *forces)
{
    mb_m3t_paper_motion(t, centre, amplitude, omega, ref, ref_rate, ref_acc);
    return mb_m3t_slider_forces(pa, ref, ref_rate, ref_acc, mode, forces);
}
