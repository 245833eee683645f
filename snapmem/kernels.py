"""Compiled kernels for what numpy cannot vectorise: sequential recursions along the band.

The one here is the LDL^T factorisation without pivoting of a symmetric band matrix, whose
pivot signs give the inertia (Sylvester's law of inertia). LAPACK has no symmetric indefinite
band factorisation, and its band eigen-solvers reduce to tridiagonal form in O(n^2 b) work,
which the profile of a traced branch showed dominating from N ~ 100 nodes; this kernel is
O(n b^2). Compiled by numba on first use and cached on disk.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def band_ldlt_inertia(lower: np.ndarray, b: int):
    """Negative and zero pivot counts of the LDL^T factorisation of a symmetric band matrix.

    Parameters
    ----------
    lower : ndarray (b + 1, n)
        Lower band storage: lower[i - j, j] = K[i, j] for 0 <= i - j <= b.
    b : int
        Half-bandwidth.

    Returns
    -------
    negative, zero : int
        Numbers of negative and of exactly zero pivots; with no zero pivot, ``negative`` is the
        number of negative eigenvalues of K. A zero pivot (K singular at a leading block) is
        replaced by a tiny positive one so the count of the rest continues.
    """
    n = lower.shape[1]
    d = np.empty(n)
    L = np.zeros((b + 1, n))          # L[i - j, j] = l_ij, unit diagonal implied
    negative = 0
    zero = 0
    scale = 0.0
    for j in range(n):
        scale = max(scale, abs(lower[0, j]))
    tiny = 1e-300 + 1e-14 * scale
    for j in range(n):
        s = lower[0, j]
        for k in range(max(0, j - b), j):
            lk = L[j - k, k]
            s -= lk * lk * d[k]
        if s < 0.0:
            negative += 1
        elif s == 0.0:
            zero += 1
            s = tiny
        d[j] = s
        for i in range(j + 1, min(n, j + b + 1)):
            t = lower[i - j, j]
            for k in range(max(0, i - b), j):
                t -= L[i - k, k] * L[j - k, k] * d[k]
            L[i - j, j] = t / s
    return negative, zero
