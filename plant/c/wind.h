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
   initialisation. u(t) is then a fixed function of t: no state evolves while stepping,
   a run is the same whatever the step, and the time-averaged variance is the target's
   over the band exactly. Below 1/600 Hz lies the 10-minute mean (the mean speed's
   convention); 50 Hz is far above the hexapod loop's 8 Hz crossover.

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
       M = (0, 0, moment_arm) x F. */

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
} mb_wind;

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

#endif
