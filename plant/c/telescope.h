#ifndef MB_TELESCOPE_H
#define MB_TELESCOPE_H
/* The telescope that moves the hexapod's base: axis profiles -> base and reference motion.
   Law: docs/conventions/telescope.md. SI (m, rad, s), every derivative analytic. The Python API
   (plant/telescope/model.py, plant/trajectory.py) and the telescope FMUs call these functions.

   Arrays are row-major. "axes" is (n, 6) with columns A, A', A'', E, E', E'': A the mount's
   azimuth angle of R_WB = Rz(A) Rx(90 deg - E), A = 180 deg - Az with Az the astronomical
   azimuth (north through east; docs/conventions/telescope.md), E the elevation. Poses are (n, 6): x, y, z, roll, pitch, yaw. Times need not be
   increasing for the C; the Python API still demands strictly increasing times. */

/* Site, lever arm, axis limits, subreflector correction and home pose (TelescopeParams).
   a_y = -b_y and a_z = -b_z are derived here, so that the home pose holds at the zenith. */
typedef struct {
    double latitude;       /* rad, geodetic, north positive */
    double longitude;      /* rad, east positive */
    double lever_arm;      /* m, axis intersection -> base along the boresight */
    double az_rate_max;    /* rad/s */
    double az_acc_max;     /* rad/s^2 */
    double el_rate_max;    /* rad/s */
    double el_acc_max;     /* rad/s^2 */
    double b_y, c_y;       /* m, dy(E) = a_y + b_y sin E + c_y cos E */
    double b_z, c_z;       /* m, dz(E) = a_z + b_z sin E + c_z cos E */
    double home[6];        /* platform pose in {B} at E = 90 deg */
} mb_tel_params;

enum mb_tel_kind {
    MB_TEL_SLEW = 0,       /* trapezoidal slew start -> target at the axis limits */
    MB_TEL_SIDEREAL = 1,   /* track (ra, dec) from utc_start */
    MB_TEL_PAPER = 2,      /* the paper's stress manoeuvre over paper_duration */
    MB_TEL_REPLAY = 3      /* a table of az/el samples, as its smoothing spline (replay_*) */
};

/* One motion profile (the telescope FMU's parameters). Every profile function evaluates
   the profile at t - start_delay (the start pointing holds before it). */
typedef struct {
    int kind;                  /* enum mb_tel_kind */
    double start_az, start_el; /* rad, slew start: astronomical azimuth, elevation */
    double target_az, target_el; /* rad, slew target: astronomical azimuth, elevation */
    double ra, dec;            /* rad, apparent (of date) right ascension and declination */
    double utc_start;          /* s, UTC at t = 0 as seconds since 1970-01-01 (Unix time) */
    double paper_duration;     /* s */
    double start_delay;        /* s */
    double ref_start[6];       /* paper: the platform reference is the quintic from ref_start */
    double ref_stop[6];        /*   to ref_stop over paper_duration (HOME_POSE -> S_BAND_POSE) */
    /* replay: a piecewise cubic in each axis over replay_n breakpoints replay_t (s, strictly
       increasing, replay_t[0] is the profile's t = 0); replay_coef (replay_n - 1, 8) per
       interval: astronomical azimuth c0..c3, elevation c0..c3 (rad) of
       c0 + c1 s + c2 s^2 + c3 s^3, s the time since the interval's start. Before the first
       and after the last breakpoint the end pointing holds (rate and acceleration 0).
       Checked once by mb_tel_replay_check; the arrays belong to the caller. */
    int replay_n;
    const double *replay_t;
    const double *replay_coef;
} mb_tel_profile;

/* Status of every function: 0 is success; otherwise the first problem found. */
enum mb_tel_status {
    MB_TEL_OK = 0,
    MB_TEL_NONFINITE = 1,          /* a parameter, profile setting or time is NaN or inf */
    MB_TEL_LATITUDE_RANGE = 2,     /* |latitude| > 90 deg */
    MB_TEL_LEVER_ARM_NEGATIVE = 3, /* lever_arm < 0 */
    MB_TEL_LIMIT_NOT_POSITIVE = 4, /* an axis rate or acceleration limit <= 0 */
    MB_TEL_ELEVATION_RANGE = 5,    /* a slew elevation outside [0, 90 deg] (1e-9 rad allowed) */
    MB_TEL_DEC_RANGE = 6,          /* |dec| > 90 deg */
    MB_TEL_ZENITH = 7,             /* |dec - latitude| < 1e-6: the source passes the zenith */
    MB_TEL_BELOW_HORIZON = 8,      /* the tracked source (or replay) has E < 0 at a time */
    MB_TEL_DURATION_NOT_POSITIVE = 9, /* paper_duration (or a quintic's duration) <= 0 */
    MB_TEL_BAD_KIND = 10,          /* profile kind not in enum mb_tel_kind */
    MB_TEL_SUPPORT_RANGE = 11,     /* a support mode's frequency < 0, damping outside [0, 1) or
                                      modal mass <= 0, or a support setting not finite */
    MB_TEL_REPLAY_TABLE = 12       /* a replay spline with < 2 breakpoints, breakpoints not
                                      finite and strictly increasing, or a coefficient not finite */
};

/* A sentence naming the problem of a status (for FMU logs). */
const char *mb_tel_status_text(int status);

/* The rate (rad/s) at which the hour angle advances. */
double mb_tel_earth_rate(void);

/* Local mean sidereal time (rad, in [0, 2 pi)) at Unix time utc (s): GMST of IAU 1982
   (Meeus 12.4) with UTC for UT1, days since J2000 = (utc - 946728000) / 86400. */
double mb_tel_lst(double longitude, double utc);

/* Checks of the parameters alone (finite, latitude, lever arm, limits). */
int mb_tel_check_params(const mb_tel_params *p);

/* A replay spline (mb_tel_profile's replay_*): MB_TEL_OK or MB_TEL_REPLAY_TABLE, with
   *first_bad the breakpoint (or interval) at fault, -1 if none. O(n): once, not per call. */
int mb_tel_replay_check(int n, const double *t, const double *coef, int *first_bad);

/* Seconds until both axes of the slew start -> target have arrived. */
int mb_tel_slew_duration(const mb_tel_params *p, double start_az, double start_el,
                         double target_az, double target_el, double *duration);

/* The profile's axes (n, 6) at the n times t (each shifted by start_delay). For
   MB_TEL_BELOW_HORIZON the axes are still filled and *first_bad (if not NULL) receives
   the index of the first time with E < 0; for MB_TEL_NONFINITE of a time, that time's
   index; otherwise -1. Any other failure leaves the axes unwritten. */
int mb_tel_axes(const mb_tel_params *p, const mb_tel_profile *prof, int n, const double *t,
                double *axes, int *first_bad);

/* Pose of {B} in {W} and its plain time derivatives, each (n, 6), from axes (n, 6). */
void mb_tel_base_motion(const mb_tel_params *p, int n, const double *axes,
                        double *pose, double *rate, double *acc);

/* (v_B, w_B, a_B, eps_B), each (n, 3) in {B}, from axes (n, 6). */
void mb_tel_base_twist(const mb_tel_params *p, int n, const double *axes,
                       double *v, double *w, double *a, double *eps);

/* Subreflector reference pose in {B} with its two time derivatives, each (n, 6). */
void mb_tel_reference_pose(const mb_tel_params *p, int n, const double *axes,
                           double *pose, double *rate, double *acc);

/* s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5 from start to stop (dim each) over duration:
   position, velocity, acceleration (n, dim) at the n times t; held outside [0, duration]. */
int mb_tel_quintic(int dim, const double *start, const double *stop, double duration,
                   int n, const double *t, double *pos, double *vel, double *acc);

/* The telescope FMU's 40 outputs at n times, rows (n, 40): base_pose, base_rate, base_acc,
   reference_pose, reference_rate, reference_acc (6 each), axis (Az = 180 deg - A, E),
   axis_rate (Az' = -A', E').
   Paper profile: the reference is the quintic ref_start -> ref_stop. *first_bad as in
   mb_tel_axes. */
int mb_tel_fmu_rows(const mb_tel_params *p, const mb_tel_profile *prof, int n,
                    const double *t, double *rows, int *first_bad);

/* The same 40 outputs plus 20 more, rows (n, 60): command_base_pose, command_base_rate,
   command_base_acc (6 each; the commanded motion, here equal to base_*), axis_acc
   (Az'' = -A'', E''). The telescope FMU's outputs with its axis servo off. */
int mb_tel_fmu_rows_full(const mb_tel_params *p, const mb_tel_profile *prof, int n,
                         const double *t, double *rows, int *first_bad);

/* The antenna's own axis servo: each axis angle x follows its command c through
   x'' = w^2 (c - x) - 2 zeta w x' (transfer function w^2 / (s^2 + 2 zeta w s + w^2),
   w = 2 pi bandwidth). state = (A, A', E, E'), the actual axes. One call advances it over
   a step h from the command axes cmd0 (at the step's start) to cmd1 (at its end), rows
   (A, A', A'', E, E', E''): classical RK4 on substeps of w h_sub <= 0.05, the command
   between the samples the cubic Hermite interpolant of (c, c') at both ends (exact for
   a cubic, so for the slew's piecewise-quadratic trapezoid except in the steps that hold
   one of its corners). bandwidth > 0, damping > 0, h >= 0. */
void mb_tel_servo_advance(double bandwidth, double damping, double h, const double *cmd0,
                          const double *cmd1, double *state);

/* The actual axes (A, A', A'', E, E', E'') of servo state (A, A', E, E') under command
   cmd: A'' and E'' from the servo's law at that instant. */
void mb_tel_servo_axes(double bandwidth, double damping, const double *cmd, const double *state,
                       double *axes);

/* The 60 outputs at time t with the servo on, from the actual axes (state) and the command
   axes cmd at t: base_*, reference_* (the gravity correction follows the actual
   elevation; paper profile: the quintic at t), axis, axis_rate, axis_acc actual,
   command_base_* from cmd. */
void mb_tel_servo_row(const mb_tel_params *p, const mb_tel_profile *prof, double bandwidth,
                      double damping, double t, const double *cmd, const double *state,
                      double *row);

/* --- the flexible feed support ------------------------------------------------------------
   The quadripod that carries the hexapod's base sways: up to two modes, each a modal coordinate
   q [m] with q'' + 2 zeta w q' + w^2 q = f, w = 2 pi frequency, and
       f = -participation (shape_t . a_B) + load_gain (shape . W) / modal_mass,
   a_B the rigid telescope's inertial acceleration of the base origin in {B} (the angular
   acceleration's own term, J shape_r . eps_B, is left out: ~1 % of it for a tip mass of a few
   tonnes at 2 m radius of gyration; gravity is left out: its slow change with elevation is the
   reference's gravity correction), W the wrench on the support's tip in {B} (force F, moment
   M at load_point: shape . W = shape_t . F + shape_r . (M + load_point x F)). A unit q moves
   the base by shape = (translation m/m, rotation rad/m) in {B}; the modes' displacement
   d = sum shape_t q, u = sum shape_r q is added to the base motion: position
   p + R_WB d, angles (roll, pitch, yaw) + Rx(roll) u (the first-order change of the Z-Y-X
   angles of R_WB exp([u]x) at pitch 0, which the alt-az base always has), with their exact
   first and second time derivatives (the base rate and acceleration stay those of the pose).
   One-way: the hexapod's reaction on the support is not fed back beyond W.
   The state, double[6] = (q1, q1', q2, q2', inertial f1, inertial f2 at the last point), is
   advanced exactly over a step (the linear mode's exact discretisation) for the inertial
   forcing linear between its values at the step's ends and the load held at its value
   during the step (the master's zero-order hold); the acceleration published at the step's
   end is the mode's q'' there under that load. A mode with frequency 0 is off. */
typedef struct {
    double frequency;      /* Hz; 0 = off (rigid) */
    double damping;        /* fraction of critical, [0, 1) */
    double modal_mass;     /* kg, > 0 */
    double participation;  /* 1: the inertial forcing per unit base acceleration along shape_t */
    double shape[6];       /* base displacement in {B} per unit q: m/m (x, y, z), rad/m (about x, y, z) */
} mb_tel_mode;

typedef struct {
    mb_tel_mode mode[2];
    double load_gain;      /* 1: the generalized force of W times this (the legs' own drag) */
    double load_point[3];  /* m, where W's moment is taken, in {B} */
    double preload[6];     /* N, N m: the steady wrench the mode starts in equilibrium under */
} mb_tel_support;

/* MB_TEL_OK or MB_TEL_SUPPORT_RANGE. */
int mb_tel_support_check(const mb_tel_support *s);

/* 1 if a mode is on (frequency > 0), else 0: the rigid base, rows untouched. */
int mb_tel_support_on(const mb_tel_support *s);

/* At the start: the modes at rest in static equilibrium under the inertial forcing of the
   rigid row and the preload; then as mb_tel_support_step with h = 0. */
int mb_tel_support_start(const mb_tel_support *s, const double *load, double *state, double *row,
                         double *sway);

/* Advance state over h from the last point to this one (row: the rigid telescope's row at
   this point, columns 0..17 = base pose, rate, acceleration), then add the support's motion
   to row's columns 0..17 and write sway (6) = (d, u), the modal displacement in {B}.
   load (6) is the wrench W held over the step. MB_TEL_NONFINITE (nothing changed) if load
   is not finite. */
int mb_tel_support_step(const mb_tel_support *s, double h, const double *load, double *state, double *row,
                        double *sway);

#endif
