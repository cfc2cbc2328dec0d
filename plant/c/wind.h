#ifndef MB_WIND_H
#define MB_WIND_H
/* Wind on the subreflector: the along-wind gust u(t) of a target spectrum (Kaimal or
   Davenport) and the quasi-steady drag wrench it puts on the hexapod's platform. The Wind
   FMUs (fmu_src/wind_fmu.py, fmu_src/native/wind.c) and plant/wind.py call these
   functions. SI throughout.

   Gust: spectral representation (Shinozuka and Deodatis 1991), a sum of 256 cosines
       u(t) = sum_k a_k cos(omega_k t + phi_k)
   over log-spaced bins of [1/600 Hz, 50 Hz]; a_k = sqrt(2 * (variance of the target
   spectrum in bin k)), the frequency drawn uniformly inside its bin and the phase
   uniformly in [0, 2 pi) from the seeded generator (plant/c/random.h), both at
   initialisation. u(t) is then a fixed function of t, the same whatever the step, and
   the time-averaged variance is the target's over the band exactly. Below 1/600 Hz lies
   the 10-minute mean (the mean speed's convention); 50 Hz is far above the hexapod loop's
   8 Hz crossover.

   Stepping (mb_wind_sample_stepped, what the Wind FMUs call): 256 sin/cos a sample cost as
   much as the hexapod loop's other FMUs together, so the FMUs turn each component's phasor
   z_k = exp(i (omega_k t + phi_k)) by exp(i omega_k h) per step h instead (4 multiplies) and
   evaluate it exactly (an anchor) every MB_WIND_ANCHOR_STEPS samples, at the first sample,
   whenever h changes and whenever t is not where the turned phasors stand (within
   MB_WIND_TIME_MATCH: time went back, a state from elsewhere). The phasors stand at
   anchor + n h, which the callers' rounded t misses by a few ulp(t); the sum corrects that
   to first order. Bound: each turn adds at most a few epsilon (2.2e-16) to a phasor's
   error, so between anchors it stays below MB_WIND_ANCHOR_STEPS * 4 epsilon ~ 1e-12 of
   each amplitude; a gust differs from the direct sum by at most ~1e-12 of the sum of its
   amplitudes, plus the direct sum's own rounding of its angles (an ulp of omega_k t + phi_k
   each: 4e-11 of the sum at 10 h, more than the turns add; tests/plant/test_wind.py holds
   it at the start and at 10 h). The phasors are state (mb_wind_phasors): the FMUs save
   them with their FMU state, and one sequence of calls gives the same bits in every FMU.

   Target one-sided spectra, sigma_u = turbulence_intensity * mean_speed, n = f L / U:
     Kaimal (IEC 61400-1 form)  S(f) = sigma_u^2 (4 L / U) / (1 + 6 n)^(5/3)
     Davenport                  S(f) = sigma_u^2 (2/3) (L / U) n / (1 + n^2)^(4/3)
   both integrating to sigma_u^2 over (0, inf). length_scale L = 0 takes the standard
   scale: Kaimal L = 8.1 * 0.7 * min(height, 60 m) (IEC 61400-1 ed. 3), Davenport
   L = 1200 m.

   Force: quasi-steady drag of the gust averaged over the drag area,
       F = 0.5 rho Cd A (U + u_A) |U + u_A|  along the wind, in {W} horizontal,
   u_A(t) = sum_k chi(f_k) a_k cos(omega_k t + phi_k) with the aerodynamic admittance of
   a compact plate (Vickery 1965), chi(f) = 1 / (1 + (2 f sqrt(A) / U)^(4/3)): gusts
   smaller than the plate do not load it all at once (chi = 0.5 at 0.87 Hz for a 6.5 m
   disc at 10 m/s). The wind comes from astronomical azimuth `direction` (north through
   east; {W} = east, north, up), turned into {B} with the base pose,
   R_WB = Rz(yaw) Ry(pitch) Rx(roll). Moment about {P}'s origin from a centre of pressure
   at moment_arm along {B}'s z (the platform's attitude relative to the base,
   micro-radians, is neglected):
       M = (0, 0, moment_arm) x F.

   Anemometer: the along-wind speed U + u_a(t) at a point `anemometer_distance` across the
   wind from the disc's centre and `anemometer_upstream` up the wind, through a first-order
   sensor lag of time constant tau. Per component, u_a keeps the drag gust's phase with
   weight gamma_k and takes an independent phase psi_k with weight sqrt(1 - gamma_k^2)
   (spectral representation of two partly coherent points, Shinozuka and Deodatis 1991),
   with Davenport's root-coherence gamma(f) = exp(-C f d / U), d the separation
   (Davenport 1961; Simiu and Scanlan, Wind Effects on Structures: C ~ 7-10 across the wind),
   and Taylor's frozen-turbulence lead of upstream / U. The lag is applied per component,
   exactly: amplitude 1 / sqrt(1 + (omega tau)^2), phase -atan(omega tau). The two
   cosines of a component share omega, so they are summed into one (amplitude, phase):
       u_a(t) = sum_k m_k cos(omega_k t + theta_k),   no state,
   evaluated from the drag gust's angle omega_k t + phi_k (one sin and cos for both).
   The coherence of u_a with the point gust u and with the area-averaged u_A (the same
   phases phi_k) is gamma(f)^2. psi_k are drawn after every other draw of the seed, so u,
   u_A and the wrench are those of the same seed without the anemometer. */

enum mb_wind_spectrum { MB_WIND_KAIMAL = 0, MB_WIND_DAVENPORT = 1 };

enum mb_wind_status {
    MB_WIND_OK = 0,
    MB_WIND_NONFINITE = 1,   /* a parameter or the base pose is NaN or inf */
    MB_WIND_BAD_SPECTRUM = 2 /* spectrum not in enum mb_wind_spectrum */
};

typedef struct {
    double mean_speed;            /* m/s, U (>= 0; 0 = no wind) */
    double turbulence_intensity;  /* 1, sigma_u / U */
    double length_scale;          /* m, L (0 = the spectrum's standard scale) */
    double height;                /* m, above ground (sets the Kaimal standard scale) */
    double air_density;           /* kg/m3 */
    double drag_coefficient;      /* 1 */
    double drag_area;             /* m2 */
    double moment_arm;            /* m, centre of pressure along {B}'s z from {P}'s origin */
    double direction;             /* rad, astronomical azimuth the wind comes from */
    double anemometer_distance;   /* m, across the wind from the disc's centre */
    double anemometer_upstream;   /* m, up the wind from the disc's centre (Taylor's lead) */
    double anemometer_time_constant; /* s, first-order lag of the sensor */
    double coherence_decay;       /* 1, Davenport's C */
    int spectrum;                 /* enum mb_wind_spectrum */
} mb_wind_params;

/* The components of one seeded gust (256 = MB_WIND_COMPONENTS, written out for cffi). */
typedef struct {
    mb_wind_params p;
    double scale;          /* m, the length scale used */
    double band_variance;  /* m2/s2, the target spectrum's variance over the band */
    double omega[256];     /* rad/s */
    double amplitude[256]; /* m/s, of the point gust u */
    double area_amplitude[256]; /* m/s, of the area-averaged gust u_A (chi(f) amplitude) */
    double phase[256];     /* rad */
    double anemometer_cos[256]; /* m/s, m_k cos(theta_k - phi_k) of the anemometer's lagged gust u_a */
    double anemometer_sin[256]; /* m/s, m_k sin(theta_k - phi_k) */
} mb_wind;

/* What mb_wind_sample_stepped keeps between samples (see Stepping above). */
#define MB_WIND_ANCHOR_STEPS 1024   /* samples from one exact evaluation to the next */
#define MB_WIND_TIME_MATCH 1e-8     /* s: t this close to where the turned phasors stand is theirs */
typedef struct {
    double anchor_time;  /* s, the last exact evaluation's (NaN: none yet) */
    double step;         /* s, the step h the rotations turn by (NaN: none yet) */
    int steps;           /* turns since the anchor */
    double c[256], s[256];   /* cos, sin of omega_k (anchor_time + steps * step) + phi_k */
    double rc[256], rs[256]; /* cos, sin of omega_k step */
} mb_wind_phasors;

/* A sentence naming the problem of a status. */
const char *mb_wind_status_text(int status);

/* The band [lowest, highest] frequency of the gust, Hz, and its number of components. */
double mb_wind_band_low(void);
double mb_wind_band_high(void);
int mb_wind_components(void);

/* Draw the gust's components from seed. */
int mb_wind_init(mb_wind *w, const mb_wind_params *p, unsigned long long seed);

/* The target spectrum's variance below frequency f (Hz): the integral of S over (0, f). */
double mb_wind_cumulative(const mb_wind *w, double f);

/* The gust u (m/s) at the n times t. */
void mb_wind_gusts(const mb_wind *w, int n, const double *t, double *u);

/* The area-averaged gust u_A (m/s) at the n times t. */
void mb_wind_area_gusts(const mb_wind *w, int n, const double *t, double *u);

/* The platform wrench (Fx, Fy, Fz in N, Mx, My, Mz in N.m, in {B}) at time t with the
   base pose (x, y, z, roll, pitch, yaw of {B} in {W}); *gust receives the point gust u(t). */
int mb_wind_wrench(const mb_wind *w, double t, const double *base_pose, double *wrench, double *gust);

/* The anemometer's reading U + u_a (m/s) at the n times t. */
void mb_wind_anemometer(const mb_wind *w, int n, const double *t, double *speed);

/* mb_wind_wrench and, from the same angles (one pass), speeds (3) = the point gust u, the
   anemometer's reading U + u_a and the speed the drag sees U + u_A (m/s): what the Wind
   FMUs publish each step. */
int mb_wind_sample(const mb_wind *w, double t, const double *base_pose, double *wrench, double *speeds);

/* Forget the phasors: the next sample evaluates them exactly. */
void mb_wind_phasors_reset(mb_wind_phasors *z);

/* mb_wind_sample at t, reached by a step h (s; 0: none) from the last sample, from the
   phasors z (see Stepping above); within ~1e-12 of mb_wind_sample's sums. A NaN or inf base
   pose leaves z as it was. */
int mb_wind_sample_stepped(const mb_wind *w, mb_wind_phasors *z, double t, double h, const double *base_pose,
                           double *wrench, double *speeds);

/* The quasi-steady drag wrench (as mb_wind_wrench's, in {B}) of the air speed `speed`
   (m/s) with drag = 0.5 rho Cd A (kg/m), the moment arm (m) and the wind's azimuth
   `direction` (rad), the base pose (x, y, z, roll, pitch, yaw of {B} in {W}). The one
   drag model of the Wind FMU and of the controller's wind feedforward. */
void mb_wind_drag(double drag, double moment_arm, double direction, double speed, const double *base_pose,
                  double *wrench);

/* One step h (s) of a first-order low-pass at cutoff (Hz) from its state to the speed
   (h < 0: the filter starts at the speed). Returns the new state. */
double mb_wind_speed_filter(double state, double speed, double cutoff, double h);

/* Wind feedforward: the leg forces (6, N) that hold the drag wrench of the measured speed
   at the platform pose `pose` (in {B}): J^T F = -gain W, J the leg Jacobian at `pose`
   (rows s, rho x s). Writes the predicted wrench W (6) and forces; returns det J (0: singular,
   forces NaN). base_joints, platform_joints, data as for plant/c/hexapod.h. */
double mb_wind_feedforward(const double *base_joints, const double *platform_joints, const double *data,
                           const double *pose, const double *base_pose, double drag, double moment_arm,
                           double direction, double speed, double gain, double *wrench, double *forces);

#endif
