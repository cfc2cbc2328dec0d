#ifndef MB_RANDOM_H
#define MB_RANDOM_H
/* Seeded pseudo-random numbers for the noise of sensor, wind and other random models:
   the same seed gives the same numbers in the Python API, the pythonfmu FMUs and the
   native FMUs (one generator, here). splitmix64 (Steele, Lea, Flood 2014): 64 bits of
   state, so an FMU saves and restores it with its other state. */
typedef struct { unsigned long long state; } mb_rng;

void mb_rng_seed(mb_rng *rng, unsigned long long seed);
/* Uniform in [0, 1) with 53 random bits. */
double mb_rng_uniform(mb_rng *rng);
/* Standard normal (Box-Muller on two uniforms; one normal per call, the second discarded
   so the sequence depends on the call count only). */
double mb_rng_normal(mb_rng *rng);
#endif
