/* Pose errors of perturbed hexapods (API in tolerance.h): a sample at a time, Newton's
   iterations on the six closure equations |p + R a_i - B_i| = l_i with the pose Jacobian
   dl/d(pose) = [s_i, (R a_i x s_i) E] (E: RPY rates -> angular velocity), as
   plant.hexapod.model's kinematics writes them. Nothing is allocated. */
#include <math.h>
#include <stddef.h>
#include "linalg.h"
#include "tolerance.h"

/* Leg lengths (6) of the hexapod (B, a) at pose x; with J (36) non-NULL also the pose Jacobian. */
static void legs(const double *B, const double *a, const double *x, double *length, double *J)
{
    double cr = cos(x[3]), sr = sin(x[3]), cp = cos(x[4]), sp = sin(x[4]), cy = cos(x[5]), sy = sin(x[5]);
    double R[9] = {cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr,
                   sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr,
                   -sp,     cp * sr,                cp * cr};
    /* columns of E: the angular velocity of a unit roll, pitch and yaw rate */
    double E[3][3] = {{cy * cp, sy * cp, -sp}, {-sy, cy, 0.0}, {0.0, 0.0, 1.0}};
    for (int i = 0; i < 6; i++) {
        const double *ai = a + 3 * i, *bi = B + 3 * i;
        double rho[3], leg[3];
        for (int c = 0; c < 3; c++) {
            rho[c] = R[3 * c] * ai[0] + R[3 * c + 1] * ai[1] + R[3 * c + 2] * ai[2];
            leg[c] = x[c] + rho[c] - bi[c];
        }
        double l = sqrt(leg[0] * leg[0] + leg[1] * leg[1] + leg[2] * leg[2]);
        length[i] = l;
        if (J == NULL)
            continue;
        double s[3] = {leg[0] / l, leg[1] / l, leg[2] / l};
        double m[3] = {rho[1] * s[2] - rho[2] * s[1], rho[2] * s[0] - rho[0] * s[2], rho[0] * s[1] - rho[1] * s[0]};
        double *row = J + 6 * i;
        for (int c = 0; c < 3; c++) {
            row[c] = s[c];
            row[3 + c] = m[0] * E[c][0] + m[1] * E[c][1] + m[2] * E[c][2];
        }
    }
}

int mb_tolerance_pose_errors(int n, const double *base_joints, const double *platform_joints,
                             const double *home_lengths, const double *samples, const double *play,
                             const double *poses, double tol, int max_iter, double *errors, double *residual)
{
    int first_bad = -1;
    for (int k = 0; k < n; k++) {
        const double *in = samples + 66 * (size_t)k, *cmd = poses + 6 * (size_t)k;
        double B[18], a[18], commanded[6], target[6], x[6], l[6], J[36], r[6], step[6], worst = INFINITY;
        for (int j = 0; j < 18; j++) {
            B[j] = base_joints[j] + in[18 + j];
            a[j] = platform_joints[j] + in[36 + j];
        }
        legs(base_joints, platform_joints, cmd, commanded, NULL);
        for (int i = 0; i < 6; i++) {
            target[i] = home_lengths[i] + in[i] + (1.0 + in[6 + i]) * (commanded[i] - home_lengths[i] + in[12 + i]);
            if (play != NULL)
                target[i] += play[6 * (size_t)k + (size_t)i];
            x[i] = cmd[i];
        }
        int ok = 0;
        for (int it = 0; it < max_iter; it++) {
            legs(B, a, x, l, J);
            worst = 0.0;
            for (int i = 0; i < 6; i++) {
                r[i] = l[i] - target[i];
                worst = fabs(r[i]) > worst || r[i] != r[i] ? fabs(r[i]) : worst;
            }
            if (worst < tol) {
                ok = 1;
                break;
            }
            if (mb_solve6(J, r, step) == 0.0)
                break;
            double move = 0.0;
            for (int i = 0; i < 6; i++) {
                x[i] -= step[i];
                if (i < 3 && !(fabs(step[i]) <= move))   /* NaN taken too */
                    move = fabs(step[i]);
            }
            if (!(move <= 10.0))   /* diverging, or NaN */
                break;
        }
        double *e = errors + 6 * (size_t)k;
        for (int i = 0; i < 6; i++)
            e[i] = ok ? x[i] - cmd[i] : NAN;
        if (!ok && first_bad < 0) {
            first_bad = k;
            *residual = worst;
        }
    }
    return first_bad;
}
