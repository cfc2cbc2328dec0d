/* Gaussian elimination for the kernels' small systems: LAPACK's call overhead costs more
   than the elimination itself at n = 3 or 6. One elimination, inlined into entry points
   of fixed n so that the compiler unrolls its loops (the same operations, the same bits). */
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

double mb_solve6(double *A, double *b, double *x) { return eliminate(6, A, b, x); }

double mb_det6(double *A) { return eliminate(6, A, NULL, NULL); }
