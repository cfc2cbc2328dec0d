/* splitmix64 and Box-Muller: small, portable, and equal bit for bit on every platform
   with IEEE doubles and a correctly rounded log/sqrt/cos (glibc's are). */
#include <math.h>
#include "random.h"

void mb_rng_seed(mb_rng *rng, unsigned long long seed)
{
    rng->state = seed;
}

static unsigned long long next(mb_rng *rng)
{
    unsigned long long z = (rng->state += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}

double mb_rng_uniform(mb_rng *rng)
{
    return (double)(next(rng) >> 11) * 0x1.0p-53;
}

double mb_rng_normal(mb_rng *rng)
{
    double u1 = 1.0 - mb_rng_uniform(rng);   /* (0, 1]: log is finite */
    double u2 = mb_rng_uniform(rng);
    return sqrt(-2.0 * log(u1)) * cos(6.283185307179586 * u2);   /* 2 pi */
}
