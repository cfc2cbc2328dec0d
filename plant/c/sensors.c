/* The sampled position and force sensors (equations in sensors.h). */
#include <math.h>
#include <string.h>
#include "sensors.h"

static double noisy(mb_rng *rng, double noise, double x)
{
    return noise > 0.0 ? x + noise * mb_rng_normal(rng) : x;
}

static double quantise(double resolution, double x)
{
    return resolution > 0.0 ? resolution * floor(x / resolution + 0.5) : x;
}

static double measure(mb_sensor *s, double resolution, double noise, double x)
{
    return quantise(resolution, noisy(&s->rng, noise, x));
}

static void push(mb_sensor *s, int n, const double *m, const double *r)
{
    double *slot = s->line + 12 * (s->count % 3);
    memcpy(slot, m, (size_t)n * sizeof(double));
    memcpy(slot + 6, r, (size_t)n * sizeof(double));
    s->count++;
}

static void read_out(const mb_sensor *s, int n, int delay_steps, double *measured, double *rate)
{
    const double *slot = s->line + 12 * ((s->count - 1 - delay_steps) % 3);
    memcpy(measured, slot, (size_t)n * sizeof(double));
    memcpy(rate, slot + 6, (size_t)n * sizeof(double));
}

void mb_sensor_start(mb_sensor *s, unsigned long long seed, int n, double resolution, double noise,
                     const double *value, double *measured, double *rate)
{
    memset(s, 0, sizeof *s);
    mb_rng_seed(&s->rng, seed);
    for (int j = 0; j < n; j++) s->previous[j] = measure(s, resolution, noise, value[j]);
    for (int k = 0; k < 3; k++) push(s, n, s->previous, s->rate);
    read_out(s, n, 0, measured, rate);
}

void mb_sensor_sample(mb_sensor *s, int n, double resolution, double noise, double rate_cutoff, int delay_steps,
                      double h, const double *value, double *measured, double *rate)
{
    double m[6];
    double a = rate_cutoff > 0.0 ? 1.0 - exp(-6.283185307179586 * rate_cutoff * h) : 1.0;   /* 2 pi */
    for (int j = 0; j < n; j++) {
        m[j] = measure(s, resolution, noise, value[j]);
        double d = (m[j] - s->previous[j]) / h;
        s->rate[j] = a < 1.0 ? s->rate[j] + a * (d - s->rate[j]) : d;
        s->previous[j] = m[j];
    }
    push(s, n, m, s->rate);
    read_out(s, n, delay_steps, measured, rate);
}

static void load_cell_push(mb_load_cell *s, int n, const double *m, int delay_steps, double *measured)
{
    memcpy(s->line + 6 * (s->count % 3), m, (size_t)n * sizeof(double));
    s->count++;
    memcpy(measured, s->line + 6 * ((s->count - 1 - delay_steps) % 3), (size_t)n * sizeof(double));
}

void mb_load_cell_start(mb_load_cell *s, unsigned long long seed, int n, double resolution, double noise,
                        const double *value, double *measured)
{
    double m[6];
    memset(s, 0, sizeof *s);
    mb_rng_seed(&s->rng, seed);
    for (int j = 0; j < n; j++) {
        s->filtered[j] = value[j];
        m[j] = quantise(resolution, noisy(&s->rng, noise, value[j]));
    }
    for (int k = 0; k < 3; k++) load_cell_push(s, n, m, 0, measured);
}

void mb_load_cell_sample(mb_load_cell *s, int n, double resolution, double noise, double bandwidth, int delay_steps,
                         double h, const double *value, double *measured)
{
    double m[6];
    double b = bandwidth > 0.0 ? 1.0 - exp(-6.283185307179586 * bandwidth * h) : 1.0;   /* 2 pi */
    for (int j = 0; j < n; j++) {
        s->filtered[j] = b < 1.0 ? s->filtered[j] + b * (value[j] - s->filtered[j]) : value[j];
        m[j] = quantise(resolution, noisy(&s->rng, noise, s->filtered[j]));
    }
    load_cell_push(s, n, m, delay_steps, measured);
}
