/* Gaussian elimination for the kernels' small systems: LAPACK's call overhead costs more
   than the elimination itself at n = 3 or 6. */
#include <math.h>
#include <stddef.h>
#include "linalg.h"

/* Eliminates A (and b when not NULL) with partial pivoting, then back-substitutes into x
   when b is given; returns det(A), 0.0 when exactly singular (x is then all NaN). */
static inline double eliminate(int n, double *A, double *b, double *x)
{
    double det = 1.0;
    for (int c = 0; c < n; c++) {
        int p = c;
        for (int r = c + 1; r < n; r++)
            if (fabs(A[r * n + c]) > fabs(A[p * n + c])) p = r;
        if (A[p * n + c] == 0.0) {
            if (b)
                for (int k = 0; k < n; k++) x[k] = NAN;
            return 0.0;
        }
        if (p != c) {
            det = -det;
            for (int k = 0; k < n; k++) {
                double tmp = A[c * n + k]; A[c * n + k] = A[p * n + k]; A[p * n + k] = tmp;
            }
            if (b) {
                double tmp = b[c]; b[c] = b[p]; b[p] = tmp;
            }
        }
        det *= A[c * n + c];
        for (int r = c + 1; r < n; r++) {
            double f = A[r * n + c] / A[c * n + c];
            for (int k = c; k < n; k++) A[r * n + k] -= f * A[c * n + k];
            if (b) b[r] -= f * b[c];
        }
    }
    if (b)
        for (int r = n - 1; r >= 0; r--) {
            double acc = b[r];
            for (int k = r + 1; k < n; k++) acc -= A[r * n + k] * x[k];
            x[r] = acc / A[r * n + r];
        }
    return det;
}

double mb_solve(int n, double *A, double *b, double *x) { return eliminate(n, A, b, x); }

#if defined(__GNUC__)
/* The elimination above at n = 6 with each row held as three pairs of columns (one
   2-double vector each, an SSE2 / NEON register): a row operation updates two columns
   per instruction, each lane the scalar operation, and a pivot swap exchanges two row
   pointers: the same operations on the same numbers, the same bits. A row operation
   that starts at an odd column also updates the column before it, below the diagonal,
   which nothing reads again. */
typedef double d2 __attribute__((vector_size(16)));
#define UNROLL _Pragma("GCC unroll 6")
typedef union { d2 v[3]; double s[6]; } row6;

static inline __attribute__((always_inline)) double eliminate6(const double *A, const double *b_in, double *x)
{
    row6 rows[6], *R[6];
    double b[6], det = 1.0;
    UNROLL
    for (int r = 0; r < 6; r++) {
        UNROLL
        for (int k = 0; k < 6; k++) rows[r].s[k] = A[6 * r + k];
        R[r] = &rows[r];
        b[r] = b_in ? b_in[r] : 0.0;
    }
    UNROLL
    for (int c = 0; c < 6; c++) {
        int p = c;
        UNROLL
        for (int r = c + 1; r < 6; r++)
            if (fabs(R[r]->s[c]) > fabs(R[p]->s[c])) p = r;
        if (R[p]->s[c] == 0.0) {
            for (int k = 0; b_in && k < 6; k++) x[k] = NAN;
            return 0.0;
        }
        if (p != c) {
            row6 *tmp = R[c]; R[c] = R[p]; R[p] = tmp;
            det = -det;
            if (b_in) {
                double t = b[c]; b[c] = b[p]; b[p] = t;
            }
        }
        const row6 *pivot = R[c];
        det *= pivot->s[c];
        UNROLL
        for (int r = c + 1; r < 6; r++) {
            double f = R[r]->s[c] / pivot->s[c];
            d2 ff = {f, f};
            UNROLL
            for (int k = c / 2; k < 3; k++) R[r]->v[k] -= ff * pivot->v[k];
            if (b_in) b[r] -= f * b[c];
        }
    }
    UNROLL
    for (int r = 5; b_in && r >= 0; r--) {
        double acc = b[r];
        UNROLL
        for (int k = r + 1; k < 6; k++) acc -= R[r]->s[k] * x[k];
        x[r] = acc / R[r]->s[r];
    }
    return det;
}
#else
static inline double eliminate6(const double *A, const double *b_in, double *x)
{
    double a[36], b[6];
    for (int k = 0; k < 36; k++) a[k] = A[k];
    for (int k = 0; b_in && k < 6; k++) b[k] = b_in[k];
    return eliminate(6, a, b_in ? b : NULL, x);
}
#endif

double mb_solve6(const double *A, const double *b, double *x) { return eliminate6(A, b, x); }

double mb_det6(const double *A) { return eliminate6(A, NULL, NULL); }
