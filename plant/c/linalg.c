/* Gaussian elimination for the kernels' small systems: LAPACK's call overhead costs more
   than the elimination itself at n = 3 or 6. */
#include <math.h>
#include "linalg.h"

double mb_solve(int n, double *A, double *b, double *x)
{
    double det = 1.0;
    for (int c = 0; c < n; c++) {
        int p = c;
        for (int r = c + 1; r < n; r++)
            if (fabs(A[r * n + c]) > fabs(A[p * n + c])) p = r;
        if (A[p * n + c] == 0.0) {
            for (int k = 0; k < n; k++) x[k] = NAN;
            return 0.0;
        }
        if (p != c) {
            det = -det;
            for (int k = 0; k < n; k++) {
                double tmp = A[c * n + k]; A[c * n + k] = A[p * n + k]; A[p * n + k] = tmp;
            }
            double tmp = b[c]; b[c] = b[p]; b[p] = tmp;
        }
        det *= A[c * n + c];
        for (int r = c + 1; r < n; r++) {
            double f = A[r * n + c] / A[c * n + c];
            for (int k = c; k < n; k++) A[r * n + k] -= f * A[c * n + k];
            b[r] -= f * b[c];
        }
    }
    for (int r = n - 1; r >= 0; r--) {
        double acc = b[r];
        for (int k = r + 1; k < n; k++) acc -= A[r * n + k] * x[k];
        x[r] = acc / A[r * n + r];
    }
    return det;
}
