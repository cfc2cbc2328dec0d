/* The gust and drag wrench of plant/c/wind.h. */
#include <math.h>
#include <stddef.h>

#include "hexapod.h"
#include "linalg.h"
#include "random.h"
#include "wind.h"

#define N_COMPONENTS 256
#define BAND_LOW (1.0 / 600.0)   /* Hz: below it, the 10-minute mean */
#define BAND_HIGH 50.0           /* Hz */
#define TWO_PI 6.283185307179586

const char *mb_wind_status_text(int status)
{
    switch (status) {
    case MB_WIND_OK: return "ok";
    case MB_WIND_NONFINITE: return "a wind parameter or the base pose is NaN or inf";
    case MB_WIND_BAD_SPECTRUM: return "spectrum must be 0 (kaimal) or 1 (davenport)";
    default: return "unknown wind status";
    }
}

double mb_wind_band_low(void) { return BAND_LOW; }
double mb_wind_band_high(void) { return BAND_HIGH; }
int mb_wind_components(void) { return N_COMPONENTS; }

/* 1 - C(f) / sigma_u^2: the fraction of the variance above f. */
static double above(const mb_wind *w, double f)
{
    double n = f * w->scale / w->p.mean_speed;
    if (w->p.spectrum == MB_WIND_KAIMAL)
        return pow(1.0 + 6.0 * n, -2.0 / 3.0);
    return pow(1.0 + n * n, -1.0 / 3.0);
}

double mb_wind_cumulative(const mb_wind *w, double f)
{
    double sigma = w->p.turbulence_intensity * w->p.mean_speed;
    if (!(sigma > 0.0)) return 0.0;
    return sigma * sigma * (1.0 - above(w, f));
}

/* The anemometer's components (wind.h), relative to the drag gust's phase phi_k so that one
   cos and sin of omega_k t + phi_k give both: the independent phases psi_k drawn last. */
static void anemometer(mb_wind *w, mb_rng *rng)
{
    const mb_wind_params *p = &w->p;
    double d = hypot(p->anemometer_distance, p->anemometer_upstream);
    for (int k = 0; k < N_COMPONENTS; k++) {
        double omega = w->omega[k], psi = TWO_PI * mb_rng_uniform(rng) - w->phase[k];
        double gamma = 1.0, lead = 0.0;
        if (p->mean_speed > 0.0) {
            gamma = exp(-p->coherence_decay * omega / TWO_PI * d / p->mean_speed);
            lead = omega * p->anemometer_upstream / p->mean_speed;
        }
        double wt = omega * p->anemometer_time_constant, rest = sqrt(1.0 - gamma * gamma);
        double re = gamma * cos(lead) + rest * cos(psi), im = gamma * sin(lead) + rest * sin(psi);
        double m = w->amplitude[k] * hypot(re, im) / sqrt(1.0 + wt * wt), delta = atan2(im, re) - atan(wt);
        w->anemometer_cos[k] = m * cos(delta);
        w->anemometer_sin[k] = m * sin(delta);
    }
}

int mb_wind_init(mb_wind *w, const mb_wind_params *p, unsigned long long seed)
{
    const double *values = &p->mean_speed;
    for (int k = 0; k < 13; k++)   /* the 13 doubles of mb_wind_params, in order */
        if (!isfinite(values[k])) return MB_WIND_NONFINITE;
    if (p->spectrum != MB_WIND_KAIMAL && p->spectrum != MB_WIND_DAVENPORT) return MB_WIND_BAD_SPECTRUM;
    w->p = *p;
    if (p->length_scale > 0.0)
        w->scale = p->length_scale;
    else if (p->spectrum == MB_WIND_KAIMAL)
        w->scale = 8.1 * 0.7 * (p->height < 60.0 ? p->height : 60.0);
    else
        w->scale = 1200.0;
    double sigma = p->turbulence_intensity * p->mean_speed;
    double sigma2 = sigma * sigma, step = log(BAND_HIGH / BAND_LOW) / N_COMPONENTS;
    int calm = !(sigma > 0.0);
    mb_rng rng;
    mb_rng_seed(&rng, seed);
    double low = BAND_LOW, above_low = calm ? 0.0 : above(w, low);
    w->band_variance = 0.0;
    for (int k = 0; k < N_COMPONENTS; k++) {
        double high = k + 1 == N_COMPONENTS ? BAND_HIGH : BAND_LOW * exp(step * (k + 1));
        double above_high = calm ? 0.0 : above(w, high);
        double variance = sigma2 * (above_low - above_high);
        double f = low + (high - low) * mb_rng_uniform(&rng);
        w->omega[k] = TWO_PI * f;
        w->phase[k] = TWO_PI * mb_rng_uniform(&rng);
        w->amplitude[k] = sqrt(2.0 * variance);
        w->area_amplitude[k] = calm ? 0.0 : w->amplitude[k] / (1.0 + pow(2.0 * f * sqrt(p->drag_area) / p->mean_speed,
                                                                           4.0 / 3.0));
        w->band_variance += variance;
        low = high;
        above_low = above_high;
    }
    anemometer(w, &rng);
    return MB_WIND_OK;
}

/* The point gust u and the area-averaged gust u_A at t (one cosine per component). */
static void gust(const mb_wind *w, double t, double *u, double *u_area)
{
    double a = 0.0, b = 0.0;
    for (int k = 0; k < N_COMPONENTS; k++) {
        double c = cos(w->omega[k] * t + w->phase[k]);
        a += w->amplitude[k] * c;
        b += w->area_amplitude[k] * c;
    }
    *u = a;
    *u_area = b;
}

/* gust() and the anemometer's gust u_a from the same angles: m_k cos(x + delta_k) =
   c_k cos x - s_k sin x. */
static void gust_and_anemometer(const mb_wind *w, double t, double *u, double *u_area, double *u_anemometer)
{
    double a = 0.0, b = 0.0, e = 0.0;
    for (int k = 0; k < N_COMPONENTS; k++) {
        double x = w->omega[k] * t + w->phase[k], c = cos(x), s = sin(x);
        a += w->amplitude[k] * c;
        b += w->area_amplitude[k] * c;
        e += w->anemometer_cos[k] * c - w->anemometer_sin[k] * s;
    }
    *u = a;
    *u_area = b;
    *u_anemometer = e;
}

void mb_wind_gusts(const mb_wind *w, int n, const double *t, double *u)
{
    double ignored;
    for (int i = 0; i < n; i++)
        gust(w, t[i], &u[i], &ignored);
}

void mb_wind_area_gusts(const mb_wind *w, int n, const double *t, double *u)
{
    double ignored;
    for (int i = 0; i < n; i++)
        gust(w, t[i], &ignored, &u[i]);
}

void mb_wind_anemometer(const mb_wind *w, int n, const double *t, double *speed)
{
    double u, u_area, u_anemometer;
    for (int i = 0; i < n; i++) {
        gust_and_anemometer(w, t[i], &u, &u_area, &u_anemometer);
        speed[i] = w->p.mean_speed + u_anemometer;
    }
}

/* The wrench and speeds (as mb_wind_sample publishes them) of the gusts u, u_A, u_a. */
static void publish(const mb_wind *w, double u, double u_area, double u_anemometer, const double *base_pose,
                    double *wrench, double *speeds)
{
    double drag = 0.5 * w->p.air_density * w->p.drag_coefficient * w->p.drag_area;
    mb_wind_drag(drag, w->p.moment_arm, w->p.direction, w->p.mean_speed + u_area, base_pose, wrench);
    speeds[0] = u;
    speeds[1] = w->p.mean_speed + u_anemometer;
    speeds[2] = w->p.mean_speed + u_area;
}

int mb_wind_sample(const mb_wind *w, double t, const double *base_pose, double *wrench, double *speeds)
{
    for (int k = 0; k < 6; k++)
        if (!isfinite(base_pose[k])) return MB_WIND_NONFINITE;
    double u, u_area, u_anemometer;
    gust_and_anemometer(w, t, &u, &u_area, &u_anemometer);
    publish(w, u, u_area, u_anemometer, base_pose, wrench, speeds);
    return MB_WIND_OK;
}

void mb_wind_phasors_reset(mb_wind_phasors *z)
{
    z->anchor_time = z->step = NAN;
    z->steps = 0;
}

/* z's phasors at t exactly: cos and sin of omega_k t + phi_k. */
static void anchor(const mb_wind *w, mb_wind_phasors *z, double t)
{
    for (int k = 0; k < N_COMPONENTS; k++) {
        double x = w->omega[k] * t + w->phase[k];
        z->c[k] = cos(x);
        z->s[k] = sin(x);
    }
    z->anchor_time = t;
    z->steps = 0;
}

int mb_wind_sample_stepped(const mb_wind *w, mb_wind_phasors *z, double t, double h, const double *base_pose,
                           double *wrench, double *speeds)
{
    for (int k = 0; k < 6; k++)
        if (!isfinite(base_pose[k])) return MB_WIND_NONFINITE;
    /* where the phasors would stand, turned once more, against t (NaN before an anchor) */
    double miss = (t - z->anchor_time) - (z->steps + 1) * h;
    if (h > 0.0 && h == z->step && fabs(miss) <= MB_WIND_TIME_MATCH && z->steps + 1 < MB_WIND_ANCHOR_STEPS) {
        for (int k = 0; k < N_COMPONENTS; k++) {   /* z_k <- z_k exp(i omega_k h) */
            double c = z->c[k], s = z->s[k];
            z->c[k] = c * z->rc[k] - s * z->rs[k];
            z->s[k] = s * z->rc[k] + c * z->rs[k];
        }
        z->steps++;
    } else {
        anchor(w, z, t);
        if (h > 0.0 && h != z->step) {   /* a new step: the rotations it turns by */
            for (int k = 0; k < N_COMPONENTS; k++) {
                z->rc[k] = cos(w->omega[k] * h);
                z->rs[k] = sin(w->omega[k] * h);
            }
            z->step = h;
        }
        miss = 0.0;
    }
    /* the phasors stand at anchor_time + steps h, which the callers' rounded t misses by a few
       ulp(t): corrected to first order in omega_k miss (|omega_k miss| <= 3e-6, its square
       below the turns' own error) */
    double a = 0.0, b = 0.0, g = 0.0;
    for (int k = 0; k < N_COMPONENTS; k++) {
        double wm = w->omega[k] * miss, c = z->c[k] - z->s[k] * wm, s = z->s[k] + z->c[k] * wm;
        a += w->amplitude[k] * c;
        b += w->area_amplitude[k] * c;
        g += w->anemometer_cos[k] * c - w->anemometer_sin[k] * s;
    }
    publish(w, a, b, g, base_pose, wrench, speeds);
    return MB_WIND_OK;
}

int mb_wind_wrench(const mb_wind *w, double t, const double *base_pose, double *wrench, double *gust_out)
{
    for (int k = 0; k < 6; k++)
        if (!isfinite(base_pose[k])) return MB_WIND_NONFINITE;
    double u, u_area;
    gust(w, t, &u, &u_area);
    double drag = 0.5 * w->p.air_density * w->p.drag_coefficient * w->p.drag_area;
    mb_wind_drag(drag, w->p.moment_arm, w->p.direction, w->p.mean_speed + u_area, base_pose, wrench);
    *gust_out = u;
    return MB_WIND_OK;
}

void mb_wind_drag(double drag, double moment_arm, double direction, double speed, const double *base_pose,
                  double *wrench)
{
    double force = drag * speed * fabs(speed);
    /* the wind comes from azimuth `direction`: it blows towards -(sin, cos, 0) in {W} */
    double fw[3] = {-force * sin(direction), -force * cos(direction), 0.0};
    double cr = cos(base_pose[3]), sr = sin(base_pose[3]);
    double cp = cos(base_pose[4]), sp = sin(base_pose[4]);
    double cy = cos(base_pose[5]), sy = sin(base_pose[5]);
    double R[9] = {cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr,
                   sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr,
                   -sp, cp * sr, cp * cr};   /* R_WB, rows */
    for (int i = 0; i < 3; i++)   /* F_B = R_WB^T F_W */
        wrench[i] = R[i] * fw[0] + R[3 + i] * fw[1] + R[6 + i] * fw[2];
    wrench[3] = -moment_arm * wrench[1];   /* (0, 0, a) x F */
    wrench[4] = moment_arm * wrench[0];
    wrench[5] = 0.0;
}

double mb_wind_speed_filter(double state, double speed, double cutoff, double h)
{
    if (h < 0.0) return speed;
    return state + (1.0 - exp(-TWO_PI * cutoff * h)) * (speed - state);
}

double mb_wind_feedforward(const double *base_joints, const double *platform_joints, const double *data,
                           const double *pose, const double *base_pose, double drag, double moment_arm,
                           double direction, double speed, double gain, double *wrench, double *forces)
{
    static const double zero[6] = {0.0};
    double M[36], h[6], J[36], ldot[6], length[6], det, JT[36], b[6];
    mb_wind_drag(drag, moment_arm, direction, speed, base_pose, wrench);
    mb_hexapod_kane(base_joints, platform_joints, data, 1, pose, zero, zero, NULL, NULL, NULL,
                    MB_HEXAPOD_BASE_NONE, 0, 1, MB_HEXAPOD_TERMS, M, h, J, ldot, length, NULL, &det);
    for (int i = 0; i < 6; i++) {
        b[i] = -gain * wrench[i];
        for (int j = 0; j < 6; j++) JT[6 * i + j] = J[6 * j + i];
    }
    return mb_solve6(JT, b, forces);
}
