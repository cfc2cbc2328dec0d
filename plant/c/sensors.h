#ifndef MB_SENSORS_H
#define MB_SENSORS_H
/* A sampled position sensor of up to 6 channels (the hexapod's leg encoders): white noise,
   quantisation, a rate estimated from the measured values, and a delay of whole samples.
   One sample k, taken every h [s] of the true value x_k:
     m_k = q round((x_k + n_k) / q)     n_k ~ N(0, noise^2) [m]; q = resolution (0: no rounding)
     d_k = (m_k - m_{k-1}) / h          backward difference [m/s]
     r_k = r_{k-1} + a (d_k - r_{k-1}), a = 1 - exp(-2 pi rate_cutoff h)  (rate_cutoff 0: a = 1)
   i.e. R(z) / M(z) = a (1 - z^-1) / (h (1 - (1 - a) z^-1)), the first-order low-pass of
   cutoff rate_cutoff [Hz] matched at its pole; the outputs are (m, r) of sample
   k - delay_steps. The state is a plain struct: an FMU saves it as bytes. */
#include "random.h"

enum { MB_SENSOR_CHANNELS = 6, MB_SENSOR_MAX_DELAY = 2 };

typedef struct {
    double previous[6];   /* m_{k-1} */
    double rate[6];       /* r_{k-1} */
    double line[36];      /* (m, r) of the last 3 samples, sample k in slot k % 3, 12 values each */
    mb_rng rng;
    long long count;      /* samples taken */
} mb_sensor;

/* The first sample (at the start time): noise and rounding, rate 0, the delay line full
   of it; seeds the noise. Writes measured (n) and rate (n). */
void mb_sensor_start(mb_sensor *s, unsigned long long seed, int n, double resolution, double noise,
                     const double *value, double *measured, double *rate);

/* The next sample of value (n) after h [s] > 0; writes the outputs of sample
   k - delay_steps (0 <= delay_steps <= MB_SENSOR_MAX_DELAY). */
void mb_sensor_sample(mb_sensor *s, int n, double resolution, double noise, double rate_cutoff, int delay_steps,
                      double h, const double *value, double *measured, double *rate);

/* A sampled force sensor of up to 6 channels (the legs' load cells), its output at
   t_k + h the sample of the input at t_k as the LegSensor's:
     y_k = y_{k-1} + b (f_k - y_{k-1}),  b = 1 - exp(-2 pi bandwidth h)  (bandwidth 0: b = 1)
     m_k = q round((y_k + n_k) / q)      n_k ~ N(0, noise^2) [N]; q = resolution (0: no rounding)
   the first-order low-pass of the cell and its amplifier matched at its pole, then the
   converter's noise and step; read out delay_steps samples late. */
typedef struct {
    double filtered[6];   /* y_{k-1} */
    double line[18];      /* m of the last 3 samples, sample k in slot k % 3 */
    mb_rng rng;
    long long count;
} mb_load_cell;

/* The first sample (at the start time): the filter at the value, the delay line full of it. */
void mb_load_cell_start(mb_load_cell *s, unsigned long long seed, int n, double resolution, double noise,
                        const double *value, double *measured);

/* The next sample of value (n) after h [s] > 0; writes the sample k - delay_steps
   (0 <= delay_steps <= MB_SENSOR_MAX_DELAY). */
void mb_load_cell_sample(mb_load_cell *s, int n, double resolution, double noise, double bandwidth, int delay_steps,
                         double h, const double *value, double *measured);
#endif
