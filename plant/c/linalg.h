#ifndef MB_LINALG_H
#define MB_LINALG_H
/* Small dense linear solves of the kernels (the hexapod's 6x6, the 3T mechanism's 3x3). */

/* x = A^-1 b by Gaussian elimination with partial pivoting; A (n x n, row-major) and b
   are overwritten. Returns det(A) (0.0 when exactly singular; x is then all NaN). */
double mb_solve(int n, double *A, double *b, double *x);

/* mb_solve at n = 6 with A and b left as they are, two columns per instruction: the
   same operations and results. */
double mb_solve6(const double *A, const double *b, double *x);

/* det(A) of a 6x6 A (left as it is) by the elimination of mb_solve without a right-hand
   side: the same value as mb_solve's. */
double mb_det6(const double *A);

#endif
