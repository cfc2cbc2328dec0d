/* The hexapod kernel's forward dynamics next to its throughput floor (benchmarks/bench_kernel.py).

   kernel_time: RK4 steps of mb_hexapod_advance_actuated as the plant FMU takes them (full
     base motion, massive legs, one substep of 1 ms), 4 forward-dynamics evaluations a step;
     seconds per evaluation.
   floor_time: per RK4 step, only the operations of that step that bound it from below at
     their throughput: `ndiv` scalar and `npdiv` two-lane divides, `nsqrt` square roots and
     `nsincos` sincos calls, each independent of the others; seconds per evaluation (a
     quarter of the step).
   digest: a 64-bit hash of every output bit of the kernel over random states of every
     base mode, leg model, speed kind, solve, reflected mass, wrench and actuator variant:
     equal digests before and after a change = the same bits. */
#define _GNU_SOURCE
#include <math.h>
#include <stdint.h>
#include <string.h>
#include <time.h>
#include "hexapod.h"

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

/* params = base_joints (18), platform_joints (18), data (11); x0 (12) a state, inputs (30)
   = commanded forces, base pose, rate, acc, wrench; act (6). */
double kernel_time(const double *params, const double *x0, const double *inputs, const double *act, long steps)
{
    const double bounds[12] = {0, 0, 0, 0, 0, 0, 1e3, 1e3, 1e3, 1e3, 1e3, 1e3};
    double x[18], outputs[24], det_min;
    double t = now();
    for (long i = 0; i < steps; i++) {
        memcpy(x, x0, sizeof x);   /* the same state each step: the work does not drift */
        mb_hexapod_advance_actuated(1, 1, params, params + 18, params + 36, act, x, inputs, 0.0, 1e-3,
                                    MB_HEXAPOD_BASE_FULL, 1, bounds, outputs, &det_min);
    }
    return (now() - t) / (4.0 * steps);
}

/* Independent operations: four accumulators per kind, arguments that change each round,
   so that neither the compiler nor the core can fold or chain them. */
double floor_time(int ndiv, int npdiv, int nsqrt, int nsincos, long steps, double *sink)
{
    typedef double d2 __attribute__((vector_size(16)));
    volatile double seed = 1.25;
    double a = seed, acc[4] = {0, 0, 0, 0}, s, c;
    d2 pacc[4] = {{0, 0}, {0, 0}, {0, 0}, {0, 0}}, one = {1.0, 1.0};
    double t = now();
    for (long i = 0; i < steps; i++) {
        double y = a + 1e-9 * (double)i;
        for (int k = 0; k < ndiv; k++) acc[k & 3] += 1.0 / (y + k);
        for (int k = 0; k < npdiv; k++) {
            d2 yy = {y + k, y - k};
            pacc[k & 3] += one / yy;
        }
        for (int k = 0; k < nsqrt; k++) acc[k & 3] += sqrt(y + k);
        for (int k = 0; k < nsincos; k++) {
            sincos(y + 0.1 * k, &s, &c);
            acc[k & 3] += s + c;
        }
    }
    t = now() - t;
    for (int k = 0; k < 4; k++) acc[k] += pacc[k][0] + pacc[k][1];
    *sink = acc[0] + acc[1] + acc[2] + acc[3];
    return t / (4.0 * steps);
}

static uint64_t rng_state;

static double uniform(double lo, double hi)
{
    rng_state = rng_state * 6364136223846793005ULL + 1442695040888963407ULL;
    return lo + (hi - lo) * (double)(rng_state >> 11) * 0x1.0p-53;
}

static uint64_t fnv(uint64_t hash, const double *x, int n)
{
    const unsigned char *b = (const unsigned char *)x;
    for (size_t i = 0; i < n * sizeof(double); i++) hash = (hash ^ b[i]) * 1099511628211ULL;
    return hash;
}

/* A random state near `home` (6) with a base far away, tilted and moving fast. */
static void random_state(const double *home, double *pose, double *rate, double *arg, double *base)
{
    for (int k = 0; k < 6; k++) {
        pose[k] = home[k] + uniform(-0.05, 0.05);
        rate[k] = uniform(-0.5, 0.5);
        arg[k] = uniform(-3000.0, 3000.0);
        base[k] = k < 3 ? uniform(-30.0, 30.0) : uniform(-1.3, 1.3);
        base[6 + k] = uniform(-2.0, 2.0);
        base[12 + k] = uniform(-3.0, 3.0);
    }
}

uint64_t digest(const double *params, const double *home, long n)
{
    const double *bj = params, *pj = params + 18, *data = params + 36;
    uint64_t hash = 14695981039346656037ULL;
    rng_state = 42;
    for (long i = 0; i < n; i++) {
        double pose[6], rate[6], arg[6], base[18], wrench[6], M[36], h[6], J[36], ld[6], l[6], out[6], det;
        for (int variant = 0; variant < 3 * 2 * 2 * 3 * 2; variant++) {
            int base_mode = variant % 3, legs = variant / 3 % 2, twist = variant / 6 % 2, solve = variant / 12 % 3;
            int ext = variant / 36;
            random_state(home, pose, rate, arg, base);
            for (int k = 0; k < 6; k++) wrench[k] = uniform(-100.0, 100.0);
            mb_hexapod_kane_ext(bj, pj, data, 1, pose, rate, arg, base, base + 6, base + 12, base_mode, legs, twist,
                                solve, ext ? 4.5 : 0.0, ext ? wrench : NULL, M, h, J, ld, l, out, &det);
            hash = fnv(hash, M, 36); hash = fnv(hash, h, 6); hash = fnv(hash, J, 36);
            hash = fnv(hash, ld, 6); hash = fnv(hash, l, 6); hash = fnv(hash, &det, 1);
            if (solve != MB_HEXAPOD_TERMS) hash = fnv(hash, out, 6);
        }
        /* advance: the four actuator variants (ideal, lag, friction + limit, reflected mass
           + wrench), RK4 and Euler, two substeps, each base mode */
        static const double acts[4][6] = {{0, 0, 0, 0, 0, 0}, {40.0, 0, 0, 0, 0, 0}, {0, 0, 50.0, 200.0, 1e-3, 2500.0},
                                          {25.0, 4.5, 20.0, 100.0, 2e-3, 0}};
        for (int variant = 0; variant < 4 * 2 * 3; variant++) {
            const double *act = acts[variant % 4];
            int rk4 = variant / 4 % 2, base_mode = variant / 8;
            double x[18], inputs[30], outputs[24], det_min;
            const double bounds[12] = {0, 0, 0, 0, 0, 0, 1e3, 1e3, 1e3, 1e3, 1e3, 1e3};
            random_state(home, x, x + 6, inputs, inputs + 6);
            for (int k = 0; k < 6; k++) {
                x[12 + k] = uniform(-3000.0, 3000.0);
                inputs[24 + k] = variant % 4 == 3 ? uniform(-100.0, 100.0) : 0.0;
            }
            int status = mb_hexapod_advance_actuated(rk4, 2, bj, pj, data, act, x, inputs, 0.3, 2e-3, base_mode, 1,
                                                     bounds, outputs, &det_min);
            double st = status;
            hash = fnv(hash, x, 18); hash = fnv(hash, outputs, 24); hash = fnv(hash, &det_min, 1);
            hash = fnv(hash, &st, 1);
        }
    }
    return hash;
}

#ifdef KERNEL_FLOOR_MAIN
#include <stdio.h>
#include <stdlib.h>
/* The driver bench_kernel.py --callgrind runs under callgrind: argv[1] a file of the
   numbers kernel_time takes (params 47, x0 18, inputs 30, act 6), argv[2] the steps. */
int main(int argc, char **argv)
{
    double v[47 + 18 + 30 + 6];
    FILE *f = argc == 3 ? fopen(argv[1], "r") : NULL;
    if (!f) return 2;
    for (size_t i = 0; i < sizeof v / sizeof v[0]; i++)
        if (fscanf(f, "%lf", &v[i]) != 1) return 2;
    fclose(f);
    printf("%g\n", kernel_time(v, v + 47, v + 65, v + 95, atol(argv[2])));
    return 0;
}
#endif
