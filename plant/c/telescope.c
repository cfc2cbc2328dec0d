/* The telescope's motion profiles and base motion (interface and law: telescope.h).

   Each expression keeps the operand order of the numpy implementation it replaced
   (plant/telescope/model.py at 73017ff), pow() where Python raised to a power of 3 or a
   Python float to a power, x * x where numpy squared an array, so that the two agree
   to the last bits (up to the libm each one's sin/cos/atan2 comes from). */
#include <math.h>
#include <stddef.h>
#include <string.h>
#include "telescope.h"

static const double PI = 3.141592653589793;        /* np.pi */
static const double TWO_PI = 6.283185307179586;    /* 2 * np.pi */
static const double EARTH_RATE = 7.2921159e-5;     /* rad/s */
static const double J2000_UNIX = 946728000.0;      /* 2000-01-01 12:00 UTC */
static const double E_TOLERANCE = 1e-9;            /* rad of rounding outside [0, 90 deg] */

const char *mb_tel_status_text(int status)
{
    switch (status) {
    case MB_TEL_OK: return "ok";
    case MB_TEL_NONFINITE: return "a parameter, profile setting or time is not finite";
    case MB_TEL_LATITUDE_RANGE: return "latitude must lie in [-90, 90] deg";
    case MB_TEL_LEVER_ARM_NEGATIVE: return "lever_arm must be >= 0";
    case MB_TEL_LIMIT_NOT_POSITIVE: return "the axis rate and acceleration limits must be > 0";
    case MB_TEL_ELEVATION_RANGE: return "slew elevation must lie in [0, 90] deg";
    case MB_TEL_DEC_RANGE: return "dec must lie in [-90, 90] deg";
    case MB_TEL_ZENITH: return "the source passes through the zenith, where the azimuth is "
                               "undefined; offset dec from the latitude";
    case MB_TEL_BELOW_HORIZON: return "the source is below the horizon";
    case MB_TEL_DURATION_NOT_POSITIVE: return "the manoeuvre's duration must be > 0";
    case MB_TEL_BAD_KIND: return "unknown profile kind (0 slew, 1 sidereal, 2 paper, 3 replay)";
    case MB_TEL_SUPPORT_RANGE: return "a support mode needs a frequency >= 0, a damping in [0, 1) and a modal "
                                      "mass > 0, and every support setting finite";
    case MB_TEL_REPLAY_TABLE: return "the replay table needs at least 2 finite, strictly increasing times "
                                     "and finite coefficients";
    default: return "unknown status";
    }
}

double mb_tel_earth_rate(void) { return EARTH_RATE; }

/* np.mod for a positive divisor: the result has the divisor's sign. */
static double floor_mod(double x, double y)
{
    double m = fmod(x, y);
    if (m != 0.0) {
        if ((y < 0) != (m < 0)) m += y;
    } else {
        m = copysign(0.0, y);
    }
    return m;
}

double mb_tel_lst(double longitude, double utc)
{
    double days = (utc - J2000_UNIX) / 86400.0;
    double T = days / 36525.0;
    double gmst = 280.46061837 + 360.98564736629 * days + 0.000387933 * pow(T, 2.0)
                  - pow(T, 3.0) / 38710000.0;
    return floor_mod(gmst * (PI / 180.0) + longitude, TWO_PI);
}

int mb_tel_check_params(const mb_tel_params *p)
{
    const double values[] = {p->latitude, p->longitude, p->lever_arm, p->az_rate_max,
                             p->az_acc_max, p->el_rate_max, p->el_acc_max, p->b_y, p->c_y,
                             p->b_z, p->c_z, p->home[0], p->home[1], p->home[2], p->home[3],
                             p->home[4], p->home[5]};
    for (size_t i = 0; i < sizeof values / sizeof values[0]; i++)
        if (!isfinite(values[i])) return MB_TEL_NONFINITE;
    if (fabs(p->latitude) > PI / 2) return MB_TEL_LATITUDE_RANGE;
    if (p->lever_arm < 0) return MB_TEL_LEVER_ARM_NEGATIVE;
    if (!(p->az_rate_max > 0 && p->az_acc_max > 0 && p->el_rate_max > 0 && p->el_acc_max > 0))
        return MB_TEL_LIMIT_NOT_POSITIVE;
    return MB_TEL_OK;
}

static int elevation_ok(double E) { return !(E < -E_TOLERANCE || E > PI / 2 + E_TOLERANCE); }

/* --- slew ------------------------------------------------------------------------- */

/* A rate- and acceleration-limited move over a signed distance starting at t = 0. */
typedef struct { double D, sign, acc_max, t_acc, peak, duration, t_dec; } trapezoid;

static trapezoid trapezoid_of(double distance, double rate_max, double acc_max)
{
    trapezoid m;
    m.D = fabs(distance);
    m.sign = distance > 0 ? 1.0 : (distance < 0 ? -1.0 : 0.0);
    m.acc_max = acc_max;
    double by_rate = rate_max / acc_max, by_distance = sqrt(m.D / acc_max);
    m.t_acc = by_distance < by_rate ? by_distance : by_rate;
    m.peak = acc_max * m.t_acc;
    m.duration = m.D == 0 ? 0.0 : m.D / m.peak + m.t_acc;   /* 2 t_acc + cruise time */
    m.t_dec = m.duration - m.t_acc;                        /* start of braking */
    return m;
}

static void trapezoid_at(const trapezoid *m, double t, double *s, double *v, double *a)
{
    double to_go = m->duration - t;
    if (t <= 0) {
        *s = 0.0; *v = 0.0; *a = 0.0;
    } else if (t < m->t_acc) {
        *s = 0.5 * m->acc_max * (t * t); *v = m->acc_max * t; *a = m->acc_max;
    } else if (t < m->t_dec) {
        *s = 0.5 * m->peak * m->t_acc + m->peak * (t - m->t_acc); *v = m->peak; *a = 0.0;
    } else if (t < m->duration) {
        *s = m->D - 0.5 * m->acc_max * (to_go * to_go); *v = m->acc_max * to_go; *a = -m->acc_max;
    } else {
        *s = m->D; *v = 0.0; *a = 0.0;
    }
    *s = m->sign * *s; *v = m->sign * *v; *a = m->sign * *a;
}

int mb_tel_slew_duration(const mb_tel_params *p, double start_az, double start_el,
                         double target_az, double target_el, double *duration)
{
    int status = mb_tel_check_params(p);
    if (status) return status;
    if (!(isfinite(start_az) && isfinite(start_el) && isfinite(target_az) && isfinite(target_el)))
        return MB_TEL_NONFINITE;
    if (!elevation_ok(start_el) || !elevation_ok(target_el)) return MB_TEL_ELEVATION_RANGE;
    double az = trapezoid_of(target_az - start_az, p->az_rate_max, p->az_acc_max).duration;
    double el = trapezoid_of(target_el - start_el, p->el_rate_max, p->el_acc_max).duration;
    *duration = el > az ? el : az;
    return MB_TEL_OK;
}

/* The spec's R_WB = Rz(A) Rx(90 deg - E) with {W} = (east, north, up) points the boresight
   at the astronomical azimuth Az = 180 deg - A (north through east): A = 180 deg - Az, and
   the same map takes A back to Az. Slew targets and sidereal tracks are astronomical;
   everything from the axes on uses A. */
static double mount_angle(double azimuth_or_angle) { return PI - azimuth_or_angle; }

/* --- sidereal tracking -------------------------------------------------------------- */

/* Unit pointing vector (north, east, up) at hour angle H and its two time derivatives. */
static void direction(double H, double dec, double lat, double u[3], double u1[3], double u2[3])
{
    double cd = cos(dec), sd = sin(dec), cl = cos(lat), sl = sin(lat);
    double cH = cos(H), sH = sin(H), w = EARTH_RATE, w2 = pow(w, 2.0);
    u[0] = sd * cl - cd * sl * cH; u[1] = -cd * sH; u[2] = sl * sd + cl * cd * cH;
    u1[0] = cd * sl * sH * w; u1[1] = -cd * cH * w; u1[2] = -cl * cd * sH * w;
    u2[0] = cd * sl * cH * w2; u2[1] = cd * sH * w2; u2[2] = -cl * cd * cH * w2;
}

/* Azimuth continuous in H whatever the sampling: atan2 jumps by -2 pi at each upper
   culmination of a source transiting south of the zenith (dec < lat) and by +2 pi at each
   lower culmination of one culminating below the north pole (dec < -lat). */
static double azimuth(double H, double north, double east, double dec, double lat)
{
    double A = atan2(east, north);
    A += TWO_PI * (dec < lat ? 1.0 : 0.0) * floor(H / TWO_PI);
    A -= TWO_PI * (dec < -lat ? 1.0 : 0.0) * floor((H - PI) / TWO_PI);
    return A;
}

/* --- the paper's stress case ------------------------------------------------------------ */

static void quintic_scalars(double duration, double t, double *s, double *ds, double *dds)
{
    double tau = t / duration;
    tau = tau < 0.0 ? 0.0 : (tau > 1.0 ? 1.0 : tau);    /* np.clip, NaN stays NaN */
    double inside = (t > 0 && t < duration) ? 1.0 : 0.0;
    double one_minus = 1 - tau;
    *s = pow(tau, 3.0) * (10 - 15 * tau + 6 * (tau * tau));
    *ds = 30 * (tau * tau) * (one_minus * one_minus) / duration * inside;
    *dds = 60 * tau * (1 - tau) * (1 - 2 * tau) / pow(duration, 2.0) * inside;
}

int mb_tel_quintic(int dim, const double *start, const double *stop, double duration,
                   int n, const double *t, double *pos, double *vel, double *acc)
{
    if (!(duration > 0)) return MB_TEL_DURATION_NOT_POSITIVE;
    for (int i = 0; i < n; i++) {
        double s, ds, dds;
        quintic_scalars(duration, t[i], &s, &ds, &dds);
        for (int k = 0; k < dim; k++) {
            double delta = stop[k] - start[k];
            pos[i * dim + k] = start[k] + s * delta;
            vel[i * dim + k] = ds * delta;
            acc[i * dim + k] = dds * delta;
        }
    }
    return MB_TEL_OK;
}

/* --- replay of a table ------------------------------------------------------------------ */

int mb_tel_replay_check(int n, const double *t, const double *coef, int *first_bad)
{
    if (first_bad) *first_bad = -1;
    if (n < 2 || !t || !coef) return MB_TEL_REPLAY_TABLE;
    for (int i = 0; i < n; i++) {
        int bad = !isfinite(t[i]) || (i > 0 && !(t[i] > t[i - 1]));
        for (int k = 0; i < n - 1 && k < 8; k++) bad = bad || !isfinite(coef[8 * i + k]);
        if (bad) {
            if (first_bad) *first_bad = i;
            return MB_TEL_REPLAY_TABLE;
        }
    }
    return MB_TEL_OK;
}

/* Azimuth (astronomical) and elevation with their two derivatives at profile time t. */
static void replay_at(const mb_tel_profile *prof, double t, double az[3], double el[3])
{
    const double *bp = prof->replay_t;
    int n = prof->replay_n, lo = 0, hi = n - 1;
    double tt = bp[0] + t, s;
    int hold = tt < bp[0] || tt > bp[n - 1];
    if (tt >= bp[n - 1]) {
        lo = n - 2;
        s = bp[n - 1] - bp[n - 2];
    } else {
        if (tt < bp[0]) tt = bp[0];
        while (hi - lo > 1) {   /* bp[lo] <= tt < bp[hi] */
            int mid = lo + (hi - lo) / 2;
            if (bp[mid] <= tt) lo = mid; else hi = mid;
        }
        s = tt - bp[lo];
    }
    const double *c = prof->replay_coef + 8 * lo;
    for (int axis = 0; axis < 2; axis++, c += 4) {
        double *out = axis ? el : az;
        out[0] = ((c[3] * s + c[2]) * s + c[1]) * s + c[0];
        out[1] = hold ? 0.0 : (3 * c[3] * s + 2 * c[2]) * s + c[1];
        out[2] = hold ? 0.0 : 6 * c[3] * s + 2 * c[2];
    }
}

/* --- a profile's axes --------------------------------------------------------------- */

static int check_profile(const mb_tel_params *p, const mb_tel_profile *prof, int n,
                         const double *t, int *first_bad)
{
    int status = mb_tel_check_params(p);
    if (status) return status;
    if (!isfinite(prof->start_delay)) return MB_TEL_NONFINITE;
    for (int i = 0; i < n; i++)
        if (!isfinite(t[i])) {
            if (first_bad) *first_bad = i;
            return MB_TEL_NONFINITE;
        }
    switch (prof->kind) {
    case MB_TEL_SLEW:
        if (!(isfinite(prof->start_az) && isfinite(prof->start_el) && isfinite(prof->target_az)
              && isfinite(prof->target_el)))
            return MB_TEL_NONFINITE;
        if (!elevation_ok(prof->start_el) || !elevation_ok(prof->target_el))
            return MB_TEL_ELEVATION_RANGE;
        return MB_TEL_OK;
    case MB_TEL_SIDEREAL:
        if (!(isfinite(prof->ra) && isfinite(prof->dec) && isfinite(prof->utc_start)))
            return MB_TEL_NONFINITE;
        if (fabs(prof->dec) > PI / 2) return MB_TEL_DEC_RANGE;
        if (fabs(prof->dec - p->latitude) < 1e-6) return MB_TEL_ZENITH;
        return MB_TEL_OK;
    case MB_TEL_PAPER:
        if (!isfinite(prof->paper_duration)) return MB_TEL_NONFINITE;
        for (int k = 0; k < 6; k++)
            if (!(isfinite(prof->ref_start[k]) && isfinite(prof->ref_stop[k])))
                return MB_TEL_NONFINITE;
        if (!(prof->paper_duration > 0)) return MB_TEL_DURATION_NOT_POSITIVE;
        return MB_TEL_OK;
    case MB_TEL_REPLAY:   /* the spline itself: mb_tel_replay_check, once */
        return prof->replay_n >= 2 && prof->replay_t && prof->replay_coef ? MB_TEL_OK : MB_TEL_REPLAY_TABLE;
    default:
        return MB_TEL_BAD_KIND;
    }
}

static void slew_axes(const mb_tel_params *p, const mb_tel_profile *prof, int n,
                      const double *t, double *axes)
{
    trapezoid az = trapezoid_of(prof->target_az - prof->start_az, p->az_rate_max, p->az_acc_max);
    trapezoid el = trapezoid_of(prof->target_el - prof->start_el, p->el_rate_max, p->el_acc_max);
    for (int i = 0; i < n; i++) {
        double ti = t[i] - prof->start_delay, *row = axes + 6 * i;
        trapezoid_at(&az, ti, &row[0], &row[1], &row[2]);
        trapezoid_at(&el, ti, &row[3], &row[4], &row[5]);
        row[0] = mount_angle(prof->start_az + row[0]);     /* targets are astronomical */
        row[1] = -row[1]; row[2] = -row[2];
        row[3] = prof->start_el + row[3];
    }
}

static int sidereal_axes(const mb_tel_params *p, const mb_tel_profile *prof, int n,
                         const double *t, double *axes, int *first_bad)
{
    double dec = prof->dec, lat = p->latitude;
    double H0 = floor_mod(mb_tel_lst(p->longitude, prof->utc_start) - prof->ra + PI, TWO_PI) - PI;
    double u0[3], u01[3], u02[3];
    direction(H0, dec, lat, u0, u01, u02);
    double wraps = floor(azimuth(H0, u0[0], u0[1], dec, lat) / TWO_PI);
    int status = MB_TEL_OK;
    for (int i = 0; i < n; i++) {
        double H = H0 + EARTH_RATE * (t[i] - prof->start_delay), u[3], u1[3], u2[3];
        direction(H, dec, lat, u, u1, u2);
        double nn = u[0], e = u[1], z = u[2], n1 = u1[0], e1 = u1[1], z1 = u1[2];
        double n2 = u2[0], e2 = u2[1], z2 = u2[2];
        double cos_E = hypot(nn, e), cos_E2 = cos_E * cos_E, *row = axes + 6 * i;
        double Az_dot = (nn * e1 - e * n1) / cos_E2;      /* astronomical azimuth's rates */
        row[1] = -Az_dot;
        row[2] = -((nn * e2 - e * n2) / cos_E2 - 2 * Az_dot * (nn * n1 + e * e1) / cos_E2);
        row[3] = atan2(z, cos_E);
        row[4] = z1 / cos_E;                              /* from sin E = z */
        row[5] = (z2 + z * (row[4] * row[4])) / cos_E;
        row[0] = mount_angle(azimuth(H, nn, e, dec, lat) - TWO_PI * wraps);
        if (row[3] < 0 && status == MB_TEL_OK) {
            status = MB_TEL_BELOW_HORIZON;
            if (first_bad) *first_bad = i;
        }
    }
    return status;
}

static void paper_axes(const mb_tel_profile *prof, int n, const double *t, double *axes)
{
    double roll_end = 45.0 * (PI / 180.0), yaw_end = 30.0 * (PI / 180.0);   /* np.radians */
    for (int i = 0; i < n; i++) {
        double s, ds, dds, *row = axes + 6 * i;
        quintic_scalars(prof->paper_duration, t[i] - prof->start_delay, &s, &ds, &dds);
        row[0] = 0.0 + s * (yaw_end - 0.0);
        row[1] = ds * (yaw_end - 0.0);
        row[2] = dds * (yaw_end - 0.0);
        row[3] = PI / 2 - (0.0 + s * (roll_end - 0.0));
        row[4] = -(ds * (roll_end - 0.0));
        row[5] = -(dds * (roll_end - 0.0));
    }
}

static int replay_axes(const mb_tel_profile *prof, int n, const double *t, double *axes, int *first_bad)
{
    int status = MB_TEL_OK;
    for (int i = 0; i < n; i++) {
        double az[3], el[3], *row = axes + 6 * i;
        replay_at(prof, t[i] - prof->start_delay, az, el);
        row[0] = mount_angle(az[0]); row[1] = -az[1]; row[2] = -az[2];
        row[3] = el[0]; row[4] = el[1]; row[5] = el[2];
        if (el[0] < 0 && status == MB_TEL_OK) {
            status = MB_TEL_BELOW_HORIZON;
            if (first_bad) *first_bad = i;
        }
    }
    return status;
}

int mb_tel_axes(const mb_tel_params *p, const mb_tel_profile *prof, int n, const double *t,
                double *axes, int *first_bad)
{
    if (first_bad) *first_bad = -1;
    int status = check_profile(p, prof, n, t, first_bad);
    if (status) return status;
    switch (prof->kind) {
    case MB_TEL_SLEW: slew_axes(p, prof, n, t, axes); return MB_TEL_OK;
    case MB_TEL_SIDEREAL: return sidereal_axes(p, prof, n, t, axes, first_bad);
    case MB_TEL_REPLAY: return replay_axes(prof, n, t, axes, first_bad);
    default: paper_axes(prof, n, t, axes); return MB_TEL_OK;
    }
}

/* --- what the axes do to the base and to the reference -------------------------------- */

static void base_row(double L, const double *ax, double *pose, double *rate, double *acc)
{
    double A = ax[0], dA = ax[1], ddA = ax[2], E = ax[3], dE = ax[4], ddE = ax[5];
    double cA = cos(A), sA = sin(A), cE = cos(E), sE = sin(E);
    double p[3] = {L * (cE * sA), L * (-cE * cA), L * sE};
    double dp_dE[3] = {L * (-sE * sA), L * (sE * cA), L * cE};
    double dp_dA[3] = {L * (cE * cA), L * (cE * sA), L * 0.0};
    double d2p_dE2[3] = {L * (-cE * sA), L * (cE * cA), L * -sE};
    double d2p_dEdA[3] = {L * (-sE * cA), L * (-sE * sA), L * 0.0};
    double d2p_dA2[3] = {L * (-cE * sA), L * (cE * cA), L * 0.0};
    for (int k = 0; k < 3; k++) {
        pose[k] = p[k];
        rate[k] = dp_dE[k] * dE + dp_dA[k] * dA;
        acc[k] = dp_dE[k] * ddE + dp_dA[k] * ddA + d2p_dE2[k] * (dE * dE)
                 + 2 * d2p_dEdA[k] * dE * dA + d2p_dA2[k] * (dA * dA);
    }
    pose[3] = PI / 2 - E; pose[4] = 0.0; pose[5] = A;
    rate[3] = -dE; rate[4] = 0.0; rate[5] = dA;
    acc[3] = -ddE; acc[4] = 0.0; acc[5] = ddA;
}

void mb_tel_base_motion(const mb_tel_params *p, int n, const double *axes,
                        double *pose, double *rate, double *acc)
{
    for (int i = 0; i < n; i++)
        base_row(p->lever_arm, axes + 6 * i, pose + 6 * i, rate + 6 * i, acc + 6 * i);
}

static void cross3(const double a[3], const double b[3], double out[3])
{
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

void mb_tel_base_twist(const mb_tel_params *p, int n, const double *axes,
                       double *v, double *w, double *a, double *eps)
{
    const double lever[3] = {0.0, 0.0, p->lever_arm};
    for (int i = 0; i < n; i++) {
        const double *ax = axes + 6 * i;
        double dA = ax[1], ddA = ax[2], dE = ax[4], ddE = ax[5], cE = cos(ax[3]), sE = sin(ax[3]);
        double *wi = w + 3 * i, *ei = eps + 3 * i, *vi = v + 3 * i, *ai = a + 3 * i;
        double c1[3], c2[3];
        wi[0] = -dE; wi[1] = dA * cE; wi[2] = dA * sE;
        ei[0] = -ddE; ei[1] = ddA * cE - dA * dE * sE; ei[2] = ddA * sE + dA * dE * cE;
        cross3(wi, lever, vi);
        cross3(ei, lever, c1);
        cross3(wi, vi, c2);
        for (int k = 0; k < 3; k++) ai[k] = c1[k] + c2[k];
    }
}

static void reference_row(const mb_tel_params *p, const double *ax, double *pose, double *rate,
                          double *acc)
{
    double E = ax[3], dE = ax[4], ddE = ax[5], cE = cos(E), sE = sin(E);
    const double coef[2][3] = {{-p->b_y, p->b_y, p->c_y}, {-p->b_z, p->b_z, p->c_z}};
    for (int k = 0; k < 6; k++) { pose[k] = p->home[k]; rate[k] = 0.0; acc[k] = 0.0; }
    for (int j = 0; j < 2; j++) {
        double a = coef[j][0], b = coef[j][1], c = coef[j][2], slope = b * cE - c * sE;  /* dΔ/dE */
        pose[1 + j] += a + b * sE + c * cE;
        rate[1 + j] = slope * dE;
        acc[1 + j] = slope * ddE - (b * sE + c * cE) * (dE * dE);
    }
}

void mb_tel_reference_pose(const mb_tel_params *p, int n, const double *axes,
                           double *pose, double *rate, double *acc)
{
    for (int i = 0; i < n; i++)
        reference_row(p, axes + 6 * i, pose + 6 * i, rate + 6 * i, acc + 6 * i);
}

/* --- the telescope FMU's outputs ------------------------------------------------------ */

/* Reference columns of one row (18..35): the paper's platform quintic at t, else the
   gravity correction at the axes' elevation. */
static void reference_columns(const mb_tel_params *p, const mb_tel_profile *prof, double t,
                              const double *ax, double *row)
{
    if (prof->kind == MB_TEL_PAPER) {   /* the paper's platform motion, same quintic */
        double sv, ds, dds;
        quintic_scalars(prof->paper_duration, t - prof->start_delay, &sv, &ds, &dds);
        for (int k = 0; k < 6; k++) {
            double delta = prof->ref_stop[k] - prof->ref_start[k];
            row[18 + k] = prof->ref_start[k] + sv * delta;
            row[24 + k] = ds * delta;
            row[30 + k] = dds * delta;
        }
    } else {
        reference_row(p, ax, row + 18, row + 24, row + 30);
    }
}

/* The 40 outputs of axes ax at time t, and with width 60 the 20 more with command = ax. */
static void fmu_row(const mb_tel_params *p, const mb_tel_profile *prof, double t, const double *ax,
                    double *row, int width)
{
    base_row(p->lever_arm, ax, row, row + 6, row + 12);
    reference_columns(p, prof, t, ax, row);
    /* the axis outputs: astronomical azimuth (the mount angle's involution), elevation */
    row[36] = mount_angle(ax[0]); row[37] = ax[3]; row[38] = -ax[1]; row[39] = ax[4];
    if (width == 60) {
        memcpy(row + 40, row, 18 * sizeof(double));
        row[58] = -ax[2]; row[59] = ax[5];
    }
}

static int fmu_rows(const mb_tel_params *p, const mb_tel_profile *prof, int n, const double *t,
                    double *rows, int *first_bad, int width)
{
    enum { CHUNK = 64 };   /* axes of CHUNK times at once on the stack: no workspace */
    int status = MB_TEL_OK;
    if (first_bad) *first_bad = -1;
    for (int i0 = 0; i0 < n; i0 += CHUNK) {
        int m = n - i0 < CHUNK ? n - i0 : CHUNK, bad;
        double axes[6 * CHUNK];
        int s = mb_tel_axes(p, prof, m, t + i0, axes, &bad);
        if (s != MB_TEL_OK && s != MB_TEL_BELOW_HORIZON) {
            if (first_bad && bad >= 0) *first_bad = i0 + bad;
            return s;
        }
        if (s == MB_TEL_BELOW_HORIZON && status == MB_TEL_OK) {
            status = s;
            if (first_bad) *first_bad = i0 + bad;
        }
        for (int j = 0; j < m; j++)
            fmu_row(p, prof, t[i0 + j], axes + 6 * j, rows + width * (i0 + j), width);
    }
    return status;
}

int mb_tel_fmu_rows(const mb_tel_params *p, const mb_tel_profile *prof, int n,
                    const double *t, double *rows, int *first_bad)
{
    return fmu_rows(p, prof, n, t, rows, first_bad, 40);
}

int mb_tel_fmu_rows_full(const mb_tel_params *p, const mb_tel_profile *prof, int n,
                         const double *t, double *rows, int *first_bad)
{
    return fmu_rows(p, prof, n, t, rows, first_bad, 60);
}

/* --- the antenna's axis servo ------------------------------------------------------------ */

static const double SERVO_MAX_WH = 0.05;   /* w h of one RK4 substep: error ~ (w h)^5 / 120 */

/* Cubic Hermite interpolant of (c0, d0) at 0 and (c1, d1) at h, at s in [0, h]. */
static double hermite(double c0, double d0, double c1, double d1, double h, double s)
{
    double u = s / h, u2 = u * u, u3 = u2 * u;
    return c0 + (c1 - c0) * (3 * u2 - 2 * u3) + h * (d0 * (u3 - 2 * u2 + u) + d1 * (u3 - u2));   /* exact at rest */
}

void mb_tel_servo_advance(double bandwidth, double damping, double h, const double *cmd0,
                          const double *cmd1, double *state)
{
    if (!(h > 0)) return;
    double w = TWO_PI * bandwidth, w2 = w * w, zw2 = 2 * damping * w;
    int n = (int)ceil(w * h / SERVO_MAX_WH);
    if (n < 1) n = 1;
    double hs = h / n;
    for (int axis = 0; axis < 2; axis++) {
        const double c0 = cmd0[3 * axis], d0 = cmd0[3 * axis + 1], c1 = cmd1[3 * axis], d1 = cmd1[3 * axis + 1];
        double x = state[2 * axis], v = state[2 * axis + 1];
        for (int k = 0; k < n; k++) {
            double s = k * hs;
            double ca = hermite(c0, d0, c1, d1, h, s), cm = hermite(c0, d0, c1, d1, h, s + 0.5 * hs);
            double cb = k == n - 1 ? c1 : hermite(c0, d0, c1, d1, h, s + hs);
            double k1x = v, k1v = w2 * (ca - x) - zw2 * v;
            double x2 = x + 0.5 * hs * k1x, v2 = v + 0.5 * hs * k1v;
            double k2x = v2, k2v = w2 * (cm - x2) - zw2 * v2;
            double x3 = x + 0.5 * hs * k2x, v3 = v + 0.5 * hs * k2v;
            double k3x = v3, k3v = w2 * (cm - x3) - zw2 * v3;
            double x4 = x + hs * k3x, v4 = v + hs * k3v;
            double k4x = v4, k4v = w2 * (cb - x4) - zw2 * v4;
            x += hs / 6 * (k1x + 2 * k2x + 2 * k3x + k4x);
            v += hs / 6 * (k1v + 2 * k2v + 2 * k3v + k4v);
        }
        state[2 * axis] = x;
        state[2 * axis + 1] = v;
    }
}

void mb_tel_servo_axes(double bandwidth, double damping, const double *cmd, const double *state,
                       double *axes)
{
    double w = TWO_PI * bandwidth;
    for (int axis = 0; axis < 2; axis++) {
        double x = state[2 * axis], v = state[2 * axis + 1];
        axes[3 * axis] = x;
        axes[3 * axis + 1] = v;
        axes[3 * axis + 2] = w * w * (cmd[3 * axis] - x) - 2 * damping * w * v;
    }
}

void mb_tel_servo_row(const mb_tel_params *p, const mb_tel_profile *prof, double bandwidth,
                      double damping, double t, const double *cmd, const double *state,
                      double *row)
{
    double actual[6];
    mb_tel_servo_axes(bandwidth, damping, cmd, state, actual);
    fmu_row(p, prof, t, actual, row, 40);
    base_row(p->lever_arm, cmd, row + 40, row + 46, row + 52);
    row[58] = -actual[2]; row[59] = actual[5];
}

/* --- the flexible feed support ------------------------------------------------------------ */

enum { MODES = 2 };

int mb_tel_support_check(const mb_tel_support *s)
{
    double sum = s->load_gain;
    for (int k = 0; k < 3; k++) sum += s->load_point[k];
    for (int k = 0; k < 6; k++) sum += s->preload[k];
    for (int j = 0; j < MODES; j++) {
        const mb_tel_mode *m = &s->mode[j];
        sum += m->participation;
        for (int k = 0; k < 6; k++) sum += m->shape[k];
        if (!(m->frequency >= 0 && m->damping >= 0 && m->damping < 1 && m->modal_mass > 0 && isfinite(m->frequency)
              && isfinite(m->modal_mass)))
            return MB_TEL_SUPPORT_RANGE;
    }
    return isfinite(sum) ? MB_TEL_OK : MB_TEL_SUPPORT_RANGE;
}

int mb_tel_support_on(const mb_tel_support *s)
{
    for (int j = 0; j < MODES; j++)
        if (s->mode[j].frequency > 0) return 1;
    return 0;
}

static double dot3(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

/* The forcing per modal mass of each mode: inertial (of the rigid row's base acceleration)
   and of a wrench. */
static void inertial_forcing(const mb_tel_support *s, const double *row, double *f)
{
    double roll = row[3], yaw = row[5], cr = cos(roll), sr = sin(roll), cy = cos(yaw), sy = sin(yaw);
    const double *acc = row + 12;   /* a_B = R_WB^T p'', R_WB = Rz(yaw) Rx(roll) */
    double a[3] = {cy * acc[0] + sy * acc[1],
                   -sy * cr * acc[0] + cy * cr * acc[1] + sr * acc[2],
                   sy * sr * acc[0] - cy * sr * acc[1] + cr * acc[2]};
    for (int j = 0; j < MODES; j++) f[j] = -s->mode[j].participation * dot3(s->mode[j].shape, a);
}

static void load_forcing(const mb_tel_support *s, const double *load, double *f)
{
    double moment[3];
    cross3(s->load_point, load, moment);
    for (int k = 0; k < 3; k++) moment[k] += load[3 + k];
    for (int j = 0; j < MODES; j++) {
        const mb_tel_mode *m = &s->mode[j];
        f[j] = s->load_gain * (dot3(m->shape, load) + dot3(m->shape + 3, moment)) / m->modal_mass;
    }
}

/* q'' + 2 zeta w q' + w^2 q = f0 + (f1 - f0) s / h over s in [0, h], exactly: the
   particular solution a + b s plus the homogeneous response e^{-zeta w s} (cos, sin wd s). */
static void mode_advance(double w, double zeta, double h, double f0, double f1, double *q, double *v)
{
    double w2 = w * w, b = (f1 - f0) / h / w2, a = (f0 - 2 * zeta * w * b) / w2;
    double x0 = *q - a, y0 = *v - b, sigma = zeta * w, wd = w * sqrt(1 - zeta * zeta);
    double c = cos(wd * h), sn = sin(wd * h), decay = exp(-sigma * h);
    *q = a + b * h + decay * (x0 * (c + sigma / wd * sn) + y0 * sn / wd);
    *v = b + decay * (y0 * (c - sigma / wd * sn) - x0 * w2 / wd * sn);
}

/* out = (R d0, R (w x d0 + d1), R (e x d0 + w x (w x d0) + 2 w x d1 + d2)): a displacement d
   fixed in a frame turning with R (angular velocity w, acceleration e in that frame),
   and its two time derivatives. */
static void carried(const double R[3][3], const double w[3], const double e[3], const double d[3][3],
                    double out[3][3])
{
    double c1[3], c2[3], c3[3], c4[3], local[3][3];
    cross3(w, d[0], c1);
    cross3(e, d[0], c2);
    cross3(w, c1, c3);
    cross3(w, d[1], c4);
    for (int k = 0; k < 3; k++) {
        local[0][k] = d[0][k];
        local[1][k] = c1[k] + d[1][k];
        local[2][k] = c2[k] + c3[k] + 2 * c4[k] + d[2][k];
    }
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++) out[i][k] = dot3(R[k], local[i]);
}

static void add_sway(const mb_tel_support *s, const double *f, const double *state, double *row, double *sway)
{
    double d[3][3] = {{0}}, u[3][3] = {{0}};   /* (value, rate, acceleration) of translation, rotation */
    for (int j = 0; j < MODES; j++) {
        const mb_tel_mode *m = &s->mode[j];
        if (!(m->frequency > 0)) continue;
        double w = TWO_PI * m->frequency, q = state[2 * j], v = state[2 * j + 1];
        double qdd = f[j] - 2 * m->damping * w * v - w * w * q;
        double mode[3] = {q, v, qdd};
        for (int i = 0; i < 3; i++)
            for (int k = 0; k < 3; k++) {
                d[i][k] += m->shape[k] * mode[i];
                u[i][k] += m->shape[3 + k] * mode[i];
            }
    }
    double roll = row[3], yaw = row[5], droll = row[9], dyaw = row[11], ddroll = row[15], ddyaw = row[17];
    double cr = cos(roll), sr = sin(roll), cy = cos(yaw), sy = sin(yaw);
    const double R[3][3] = {{cy, -sy * cr, sy * sr}, {sy, cy * cr, -cy * sr}, {0.0, sr, cr}};
    const double Rx[3][3] = {{1.0, 0.0, 0.0}, {0.0, cr, -sr}, {0.0, sr, cr}};
    const double w_B[3] = {droll, dyaw * sr, dyaw * cr};
    const double e_B[3] = {ddroll, ddyaw * sr + dyaw * droll * cr, ddyaw * cr - dyaw * droll * sr};
    const double w_x[3] = {droll, 0.0, 0.0}, e_x[3] = {ddroll, 0.0, 0.0};
    double dp[3][3], de[3][3];
    carried(R, w_B, e_B, d, dp);
    carried(Rx, w_x, e_x, u, de);
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++) {
            row[6 * i + k] += dp[i][k];
            row[6 * i + 3 + k] += de[i][k];
        }
    for (int k = 0; k < 3; k++) {
        sway[k] = d[0][k];
        sway[3 + k] = u[0][k];
    }
}

static int load_finite(const double *load)
{
    for (int k = 0; k < 6; k++)
        if (!isfinite(load[k])) return 0;
    return 1;
}

int mb_tel_support_start(const mb_tel_support *s, const double *load, double *state, double *row, double *sway)
{
    if (!load_finite(load)) return MB_TEL_NONFINITE;
    double pre[MODES];
    inertial_forcing(s, row, state + 4);
    load_forcing(s, s->preload, pre);
    for (int j = 0; j < MODES; j++) {
        double w = TWO_PI * s->mode[j].frequency;
        state[2 * j] = s->mode[j].frequency > 0 ? (state[4 + j] + pre[j]) / (w * w) : 0.0;
        state[2 * j + 1] = 0.0;
    }
    return mb_tel_support_step(s, 0.0, load, state, row, sway);
}

int mb_tel_support_step(const mb_tel_support *s, double h, const double *load, double *state, double *row,
                        double *sway)
{
    if (!load_finite(load)) return MB_TEL_NONFINITE;
    double inertial[MODES], loaded[MODES], f[MODES];
    inertial_forcing(s, row, inertial);
    load_forcing(s, load, loaded);
    for (int j = 0; j < MODES; j++) {
        const mb_tel_mode *m = &s->mode[j];
        if (h > 0 && m->frequency > 0)
            mode_advance(TWO_PI * m->frequency, m->damping, h, state[4 + j] + loaded[j], inertial[j] + loaded[j],
                         &state[2 * j], &state[2 * j + 1]);
        state[4 + j] = inertial[j];
        f[j] = inertial[j] + loaded[j];
    }
    add_sway(s, f, state, row, sway);
    return MB_TEL_OK;
}
