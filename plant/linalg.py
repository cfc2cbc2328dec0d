"""Small dense linear solves inside compiled kernels (the hexapod's 6x6, the 3T
mechanism's 3x3): numba's np.linalg.solve allocates and goes through LAPACK, which costs
more than the elimination itself at these sizes."""
import numpy as np
from numba import njit


@njit(cache=True)
def solve(A, b, x):
    """x = A^-1 b by Gaussian elimination with partial pivoting (n = A.shape[0]); A and b
    are overwritten. Returns det(A) (0.0 when exactly singular, x then left as NaN)."""
    n = A.shape[0]
    det = 1.0
    for c in range(n):
        p = c
        for r in range(c + 1, n):
            if abs(A[r, c]) > abs(A[p, c]):
                p = r
        if A[p, c] == 0.0:
            x[:] = np.nan
            return 0.0
        if p != c:
            det = -det
            for k in range(n):
                A[c, k], A[p, k] = A[p, k], A[c, k]
            b[c], b[p] = b[p], b[c]
        det *= A[c, c]
        for r in range(c + 1, n):
            f = A[r, c] / A[c, c]
            for k in range(c, n):
                A[r, k] -= f * A[c, k]
            b[r] -= f * b[c]
    for r in range(n - 1, -1, -1):
        acc = b[r]
        for k in range(r + 1, n):
            acc -= A[r, k] * x[k]
        x[r] = acc / A[r, r]
    return det
