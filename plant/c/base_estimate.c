/* Base-motion estimates from axis encoders or an IMU (interface and law: base_estimate.h). */
#include <math.h>
#include "base_estimate.h"
#include "telescope.h"

static const double PI = 3.141592653589793;
static const double TWO_PI = 6.283185307179586;

int mb_bs_check(const mb_bs_params *p)
{
    const double v[] = {p->encoder_resolution, p->rate_cutoff, p->gyro_noise_density, p->gyro_bias,
                        p->accel_noise_density, p->accel_bias, p->lever_arm, p->imu_alignment[0],
                        p->imu_alignment[1], p->imu_alignment[2]};
    for (int k = 0; k < 10; k++)
        if (!isfinite(v[k])) return 1;
    if (p->encoder_resolution < 0 || p->rate_cutoff < 0 || p->gyro_noise_density < 0
        || p->accel_noise_density < 0 || p->lever_arm < 0)
        return 1;
    return p->source == MB_BS_ENCODERS || p->source == MB_BS_IMU ? 0 : 1;
}

double mb_bs_quantise(double angle, double resolution)
{
    return resolution > 0 ? resolution * nearbyint(angle / resolution) : angle;
}

/* The base motion of axes (A, A', A'', E, E', E'') through the telescope kernel. */
static void motion(double lever_arm, const double *axes, double *estimate)
{
    mb_tel_params t = {0};
    t.lever_arm = lever_arm;
    mb_tel_base_motion(&t, 1, axes, estimate, estimate + 6, estimate + 12);
}

/* The mount angles (A, E) the encoders read from (Az, E). */
static void read_encoders(const mb_bs_params *p, const double *axis, double *angle)
{
    angle[0] = PI - mb_bs_quantise(axis[0], p->encoder_resolution);
    angle[1] = mb_bs_quantise(axis[1], p->encoder_resolution);
}

/* v in {B} -> {W}: R_WB = Rz(A) Rx(r), r = roll, A = yaw (pose columns 3 and 5). */
static void to_world(const double *pose, const double *v, double *out)
{
    double cr = cos(pose[3]), sr = sin(pose[3]), cy = cos(pose[5]), sy = sin(pose[5]);
    double x = v[0], y = cr * v[1] - sr * v[2], z = sr * v[1] + cr * v[2];
    out[0] = cy * x - sy * y;
    out[1] = sy * x + cy * y;
    out[2] = z;
}

/* d = (R - 1) v for the IMU's misalignment R = Rz(yaw) Ry(pitch) Rx(roll). */
static void misalignment(const double *rpy, const double *v, double *d)
{
    double cr = cos(rpy[0]), sr = sin(rpy[0]), cp = cos(rpy[1]), sp = sin(rpy[1]), cy = cos(rpy[2]),
           sy = sin(rpy[2]);
    double R[9] = {cy * cp - 1, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr,
                   sy * cp, sy * sp * sr + cy * cr - 1, sy * sp * cr - cy * sr,
                   -sp, cp * sr, cp * cr - 1};
    for (int k = 0; k < 3; k++) d[k] = R[3 * k] * v[0] + R[3 * k + 1] * v[1] + R[3 * k + 2] * v[2];
}

/* v in {W} -> {B}: the transpose of to_world. */
static void from_world(const double *pose, const double *v, double *out)
{
    double cr = cos(pose[3]), sr = sin(pose[3]), cy = cos(pose[5]), sy = sin(pose[5]);
    double x = cy * v[0] + sy * v[1], y = -sy * v[0] + cy * v[1];
    out[0] = x;
    out[1] = cr * y + sr * v[2];
    out[2] = -sr * y + cr * v[2];
}

/* The gyro's axis rates (A', E') from the true base motion, with noise and bias. */
static void gyro_rates(const mb_bs_params *p, double h, const double *base_pose, const double *base_rate,
                       mb_rng *rng, double *rates)
{
    double E = PI / 2 - base_pose[3], dE = -base_rate[3], dA = base_rate[5];
    double w[3] = {-dE, dA * cos(E), dA * sin(E)}, sigma = p->gyro_noise_density / sqrt(h);
    double d[3];
    misalignment(p->imu_alignment, w, d);
    for (int k = 0; k < 3; k++) w[k] += d[k] + p->gyro_bias + sigma * mb_rng_normal(rng);
    double cE = cos(E), sE = sin(E);   /* the estimator's E: the true one to within the encoder */
    rates[0] = w[1] * cE + w[2] * sE;
    rates[1] = -w[0];
}

void mb_bs_start(const mb_bs_params *p, unsigned long long seed, const double *axis,
                 const double *axis_rate, const double *base_pose, const double *base_rate,
                 const double *base_acc, mb_bs_state *s, double *estimate)
{
    (void)base_pose; (void)base_rate; (void)base_acc;
    mb_rng rng;
    mb_rng_seed(&rng, seed);
    s->rng = rng.state;
    read_encoders(p, axis, s->angle);
    s->rate[0] = -axis_rate[0];
    s->rate[1] = axis_rate[1];
    s->acc[0] = s->acc[1] = 0.0;
    double axes[6] = {s->angle[0], s->rate[0], 0.0, s->angle[1], s->rate[1], 0.0};
    motion(p->lever_arm, axes, estimate);
}

void mb_bs_step(const mb_bs_params *p, double h, const double *axis, const double *base_pose,
                const double *base_rate, const double *base_acc, mb_bs_state *s, double *estimate)
{
    double a = p->rate_cutoff > 0 ? 1 - exp(-TWO_PI * p->rate_cutoff * h) : 1.0;
    double angle[2], rate[2];
    mb_rng rng = {s->rng};
    read_encoders(p, axis, angle);
    if (p->source == MB_BS_IMU) {
        gyro_rates(p, h, base_pose, base_rate, &rng, rate);
    } else {
        for (int k = 0; k < 2; k++) rate[k] = s->rate[k] + a * ((angle[k] - s->angle[k]) / h - s->rate[k]);
    }
    for (int k = 0; k < 2; k++) {
        s->acc[k] += a * ((rate[k] - s->rate[k]) / h - s->acc[k]);
        s->angle[k] = angle[k];
        s->rate[k] = rate[k];
    }
    double axes[6] = {s->angle[0], s->rate[0], s->acc[0], s->angle[1], s->rate[1], s->acc[1]};
    motion(p->lever_arm, axes, estimate);
    if (p->source == MB_BS_IMU) {   /* translation from the accelerometer, errors in the base's axes */
        double e[3], sigma = p->accel_noise_density / sqrt(h), world[3], a[3], d[3];
        for (int k = 0; k < 3; k++) e[k] = p->accel_bias + sigma * mb_rng_normal(&rng);
        from_world(base_pose, base_acc, a);   /* the misalignment's error (R - 1) a, in the base's axes */
        misalignment(p->imu_alignment, a, d);
        for (int k = 0; k < 3; k++) e[k] += d[k];
        to_world(base_pose, e, world);
        for (int k = 0; k < 3; k++) estimate[12 + k] = base_acc[k] + world[k];
    }
    s->rng = rng.state;
}
