"""Compiled kernels for what numpy cannot vectorise: sequential recursions along the band.

The first is the LDL^T factorisation without pivoting of a symmetric band matrix, whose pivot
signs give the inertia (Sylvester's law of inertia) and whose factors solve with K wherever
they are stable (snapmem.kernels.banded checks their growth and falls back to LAPACK's pivoted band LU).
LAPACK has no symmetric indefinite band factorisation, and its band eigen-solvers reduce to
tridiagonal form in O(n^2 b) work; this kernel is O(n b^2) (measurements: docs/performance.md).
Compiled by numba on first use and cached on disk.

Also here: the refinement policies of the bordered solves (``REFINE_*``, :func:`needs_refinement`),
which :class:`snapmem.kernels.banded.BorderedLU` and :func:`snapmem.kernels.bordered.bordered_solve`
both take.
"""

from __future__ import annotations

import numpy as np
from snapmem._lazy import njit


@njit(cache=True, nogil=True, inline="always")
def band_ldlt(lower: np.ndarray, b: int):
    """LDL^T factorisation without pivoting of a symmetric band matrix: factors, inertia, growth.

    Parameters
    ----------
    lower : ndarray (b + 1, n)
        Lower band storage: lower[i - j, j] = K[i, j] for 0 <= i - j <= b.
    b : int
        Half-bandwidth.

    Returns
    -------
    F : ndarray (n, b + 1)
        F[j, 0] = d_j and F[j, m] = L[j + m, j] (unit diagonal implied): one row per column of L,
        so the factors are a quarter of LAPACK's general band storage and are read in one stream.
    negative, zero : int
        Numbers of negative and of exactly zero pivots; with no zero pivot, ``negative`` is the
        number of negative eigenvalues of K (Sylvester). A zero pivot (K singular at a leading
        block) is replaced by a tiny positive one so the count of the rest continues.
    growth : float
        max_i sum_k L_ik^2 |d_k| over the largest |K_ij|: 1 for a positive definite K. The
        factorisation is backward stable with an error of order eps * growth * |K| (the bound of
        |L| |D| |L^T|); without pivoting a small pivot inside an indefinite K makes it large.
    """
    n = lower.shape[1]
    F = np.empty((n, b + 1))
    negative = 0
    zero = 0
    scale = 0.0                       # largest |K_ij| so far (one pass: the band is read once)
    gamma = 0.0
    for j in range(n):
        s = lower[0, j]
        scale = max(scale, abs(s))
        g = 0.0
        for k in range(max(0, j - b), j):
            lk = F[k, j - k]
            t = lk * lk * F[k, 0]
            s -= t
            g += abs(t)
        last = min(n, j + b + 1)
        if s < 0.0:
            negative += 1
        elif s == 0.0:
            zero += 1
            for i in range(j + 1, last):          # the column's entries in the scale first (the loop
                scale = max(scale, abs(lower[i - j, j]))  # below takes them again: max is idempotent)
            s = 1e-300 + 1e-14 * scale
        F[j, 0] = s
        gamma = max(gamma, g + abs(s))
        for i in range(j + 1, last):
            t = lower[i - j, j]
            scale = max(scale, abs(t))
            for k in range(max(0, i - b), j):
                t -= F[k, i - k] * F[k, j - k] * F[k, 0]
            F[j, i - j] = t / s
        for m in range(last - j, b + 1):
            F[j, m] = 0.0
    return F, negative, zero, gamma / (scale if scale > 0.0 else 1.0)


@band_ldlt.python_twin
def _band_ldlt_python(lower, b):
    """:func:`band_ldlt`'s loops on Python floats (the kernel's operations, in its order)."""
    n = lower.shape[1]
    band = lower.tolist()
    F = [[0.0] * (b + 1) for _ in range(n)]
    negative = 0
    zero = 0
    scale = 0.0
    gamma = 0.0
    diagonal = band[0]
    for j in range(n):
        s = diagonal[j]
        scale = max(scale, abs(s))
        g = 0.0
        Fj = F[j]
        for k in range(max(0, j - b), j):
            Fk = F[k]
            lk = Fk[j - k]
            t = lk * lk * Fk[0]
            s -= t
            g += abs(t)
        for i in range(j + 1, min(n, j + b + 1)):
            scale = max(scale, abs(band[i - j][j]))
        if s < 0.0:
            negative += 1
        elif s == 0.0:
            zero += 1
            s = 1e-300 + 1e-14 * scale
        Fj[0] = s
        gamma = max(gamma, g + abs(s))
        for i in range(j + 1, min(n, j + b + 1)):
            t = band[i - j][j]
            for k in range(max(0, i - b), j):
                Fk = F[k]
                t -= Fk[i - k] * Fk[j - k] * Fk[0]
            Fj[i - j] = t / s
    return np.array(F, dtype=np.float64).reshape(n, b + 1), negative, zero, gamma / (scale if scale > 0.0 else 1.0)


@njit(cache=True, nogil=True)
def band_ldlt_solve(F: np.ndarray, x: np.ndarray):
    """Solve L D L^T x = rhs in place, x of shape (n, m) holding the m right-hand sides on entry
    (F from :func:`band_ldlt`): a forward and a backward pass over the factors, all columns at once."""
    if x.shape[1] == 1:
        _ldlt_solve_vector(F, x[:, 0])
        return x
    n, b = F.shape[0], F.shape[1] - 1
    cols = x.shape[1]
    for j in range(n):
        for m in range(1, min(b, n - 1 - j) + 1):
            l = F[j, m]
            for c in range(cols):
                x[j + m, c] -= l * x[j, c]
    for j in range(n - 1, -1, -1):
        inv = 1.0 / F[j, 0]
        for c in range(cols):
            s = x[j, c] * inv
            for m in range(1, min(b, n - 1 - j) + 1):
                s -= F[j, m] * x[j + m, c]
            x[j, c] = s
    return x


@band_ldlt_solve.python_twin
def _band_ldlt_solve_python(F, x):
    """:func:`band_ldlt_solve` on Python floats, a row of right-hand sides at a time (each entry
    gets the kernel's operations, in its order)."""
    if x.shape[1] == 1:
        _ldlt_solve_vector(F, x[:, 0])
        return x
    n, b = F.shape[0], F.shape[1] - 1
    factors = F.tolist()
    rows = x.tolist()
    for j in range(n):
        row = rows[j]
        Fj = factors[j]
        for m in range(1, min(b, n - 1 - j) + 1):
            l = Fj[m]
            rows[j + m] = [t - l * r for t, r in zip(rows[j + m], row)]
    for j in range(n - 1, -1, -1):
        Fj = factors[j]
        inv = 1.0 / Fj[0]
        s = [r * inv for r in rows[j]]
        for m in range(1, min(b, n - 1 - j) + 1):
            l = Fj[m]
            s = [t - l * r for t, r in zip(s, rows[j + m])]
        rows[j] = s
    x[:] = rows
    return x


@njit(cache=True, nogil=True, inline="always")
def _ldlt_solve_vector(F, x):
    """:func:`band_ldlt_solve` for one right-hand side (its own loop: faster than the loop over columns)."""
    n, b = F.shape[0], F.shape[1] - 1
    for j in range(n):
        xj = x[j]
        for m in range(1, min(b, n - 1 - j) + 1):
            x[j + m] -= F[j, m] * xj
    for j in range(n - 1, -1, -1):
        s = x[j] * (1.0 / F[j, 0])                  # as the columns' loop rounds it
        for m in range(1, min(b, n - 1 - j) + 1):
            s -= F[j, m] * x[j + m]
        x[j] = s


@_ldlt_solve_vector.python_twin
def _ldlt_solve_vector_python(F, x):
    """:func:`_ldlt_solve_vector` on Python floats."""
    n, b = F.shape[0], F.shape[1] - 1
    factors = F.tolist()
    v = x.tolist()
    for j in range(n):
        xj = v[j]
        Fj = factors[j]
        for m in range(1, min(b, n - 1 - j) + 1):
            v[j + m] -= Fj[m] * xj
    for j in range(n - 1, -1, -1):
        Fj = factors[j]
        s = v[j] * (1.0 / Fj[0])
        for m in range(1, min(b, n - 1 - j) + 1):
            s -= Fj[m] * v[j + m]
        v[j] = s
    x[:] = v


@njit(cache=True, nogil=True)
def orthonormal(X: np.ndarray) -> np.ndarray:
    """Q of the QR factorisation of X (n, m), each column oriented along X's (diag(R) > 0): Gram-Schmidt
    with one re-orthogonalisation (loops, not numba's LAPACK bindings, which are slow to compile)."""
    n, m = X.shape
    Q = X.copy()
    r = np.empty(m)
    for c in range(m):
        for _ in range(2):
            r[:c] = 0.0
            for i in range(n):
                for d in range(c):
                    r[d] += Q[i, d] * Q[i, c]
            for i in range(n):
                for d in range(c):
                    Q[i, c] -= r[d] * Q[i, d]
        norm = 0.0
        for i in range(n):
            norm += Q[i, c] * Q[i, c]
        norm = np.sqrt(norm)
        for i in range(n):
            Q[i, c] /= norm
    return Q


def sum_in_order(values: np.ndarray):
    """values[0] + values[1] + ... along the first axis, added in sequence from 0.0, as a compiled
    loop's ``total += v`` rounds it (``np.add.accumulate`` adds strictly in order; ``np.sum``
    adds pairwise). The Python twins' sums. 0.0 (or zeros) for no values."""
    if values.shape[0] == 0:
        return np.zeros(values.shape[1:])[()]
    return 0.0 + np.add.accumulate(values, axis=0)[-1]


@orthonormal.python_twin
def _orthonormal_python(X):
    """:func:`orthonormal` a column at a time, each sum over rows in the kernel's order (:func:`sum_in_order`)."""
    n, m = X.shape
    Q = X.copy()
    for c in range(m):
        for _ in range(2):
            if c:
                r = sum_in_order(Q[:, :c] * Q[:, c:c + 1])
                for d in range(c):
                    Q[:, c] -= r[d] * Q[:, d]
        norm = np.sqrt(sum_in_order(Q[:, c] * Q[:, c]))
        Q[:, c] /= norm
    return Q


@njit(cache=True, nogil=True)
def symmetric_eig(A: np.ndarray):
    """Eigenvalues and eigenvectors (columns) of a small symmetric matrix by cyclic Jacobi rotations,
    to rounding (the subspace iteration's m x m Rayleigh-Ritz matrix; m = k + 4)."""
    m = A.shape[0]
    A = A.copy()
    V = np.zeros((m, m))                            # the identity (a loop: numba's np.eye compiles slowly)
    for p in range(m):
        V[p, p] = 1.0
    for _ in range(60):
        off = 0.0
        total = 0.0
        for p in range(m):
            for q in range(m):
                total += A[p, q] * A[p, q]
                if p != q:
                    off += A[p, q] * A[p, q]
        if off <= 1e-32 * total:
            break
        for p in range(m - 1):
            for q in range(p + 1, m):
                apq = A[p, q]
                if apq == 0.0:
                    continue
                theta = (A[q, q] - A[p, p]) / (2.0 * apq)
                t = (1.0 if theta >= 0.0 else -1.0) / (abs(theta) + np.sqrt(theta * theta + 1.0))
                c = 1.0 / np.sqrt(t * t + 1.0)
                s = t * c
                for k in range(m):
                    akp, akq = A[k, p], A[k, q]
                    A[k, p], A[k, q] = c * akp - s * akq, s * akp + c * akq
                for k in range(m):
                    apk, aqk = A[p, k], A[q, k]
                    A[p, k], A[q, k] = c * apk - s * aqk, s * apk + c * aqk
                for k in range(m):
                    vkp, vkq = V[k, p], V[k, q]
                    V[k, p], V[k, q] = c * vkp - s * vkq, s * vkp + c * vkq
    w = np.empty(m)
    for p in range(m):
        w[p] = A[p, p]
    return w, V


@njit(cache=True, nogil=True)
def ritz_step(V: np.ndarray, W: np.ndarray):
    """One step of inverse subspace iteration with Rayleigh-Ritz on K^-1.

    V (n, m) has orthonormal columns and W = K^-1 V. Returns the Ritz values of K on span(W),
    nearest zero first (m,), and the next V: the Ritz vectors W y orthonormalised, each oriented
    along its W y so that vectors keep their sign from one iteration (or state) to the next.
    """
    n, m = V.shape
    H = np.zeros((m, m))
    for i in range(n):
        for a in range(m):
            for c in range(m):
                H[a, c] += V[i, a] * W[i, c]
    for a in range(m):
        for c in range(a):
            H[a, c] = H[c, a] = 0.5 * (H[a, c] + H[c, a])
    mu, Y = symmetric_eig(H)                        # Ritz values of K^-1 on span(V)
    order = np.empty(m, dtype=np.int64)             # by |mu| descending: nearest zero in K first
    for a in range(m):
        order[a] = a
    for a in range(1, m):
        c = a
        while c > 0 and abs(mu[order[c]]) > abs(mu[order[c - 1]]):
            order[c], order[c - 1] = order[c - 1], order[c]
            c -= 1
    X = np.zeros((n, m))
    for i in range(n):
        for c in range(m):
            s = 0.0
            for a in range(m):
                s += W[i, a] * Y[a, order[c]]
            X[i, c] = s
    theta = np.empty(m)
    for c in range(m):
        theta[c] = 1.0 / mu[order[c]]
    return theta, orthonormal(X)


@ritz_step.python_twin
def _ritz_step_python(V, W):
    """:func:`ritz_step` on whole arrays, each sum in the kernel's order (see :func:`_orthonormal_python`)."""
    n, m = V.shape
    H = sum_in_order(V[:, :, None] * W[:, None, :])
    for a in range(m):
        for c in range(a):
            H[a, c] = H[c, a] = 0.5 * (H[a, c] + H[c, a])
    mu, Y = symmetric_eig(H)
    order = list(range(m))
    for a in range(1, m):
        c = a
        while c > 0 and abs(mu[order[c]]) > abs(mu[order[c - 1]]):
            order[c], order[c - 1] = order[c - 1], order[c]
            c -= 1
    X = np.zeros((n, m))
    Yo = Y[:, order]
    for a in range(m):
        X += W[:, a:a + 1] * Yo[a]
    theta = 1.0 / mu[order]
    return theta, orthonormal(X)


@njit(cache=True, nogil=True)
def band_matvec(lower: np.ndarray, x: np.ndarray):
    """K @ x for a symmetric band matrix given by its lower band (b + 1, n) (as :func:`band_ldlt`)
    and x of shape (n, m): one pass."""
    b, n = lower.shape[0] - 1, lower.shape[1]
    cols = x.shape[1]
    y = np.empty_like(x)
    for c in range(cols):
        for i in range(n):
            y[i, c] = lower[0, i] * x[i, c]
    for j in range(n):
        for m in range(1, min(b, n - 1 - j) + 1):
            k = lower[m, j]
            for c in range(cols):
                y[j + m, c] += k * x[j, c]
                y[j, c] += k * x[j + m, c]
    return y


@band_matvec.python_twin
def _band_matvec_python(lower, x):
    """:func:`band_matvec` by diagonals: each y[i] gets the kernel's terms in the kernel's order (the
    diagonal, then K[i, i - m] x[i - m] for m = b..1, then K[i, i + m] x[i + m] for m = 1..b)."""
    b, n = lower.shape[0] - 1, lower.shape[1]
    y = lower[0][:, None] * x
    for m in range(min(b, n - 1), 0, -1):
        y[m:] += lower[m, :n - m][:, None] * x[:n - m]
    for m in range(1, min(b, n - 1) + 1):
        y[:n - m] += lower[m, :n - m][:, None] * x[m:]
    return y


#: Refinement policies of a bordered solve [[A, B], [C^T, D]] x = rhs by block elimination:
#: never refine; refine (one step) where the Schur complement S = D - C^T A^-1 B shows
#: cancellation (a diagonal entry below ``CANCELLATION`` of its terms: A near singular, as at a
#: fold); always refine (continuation's extended systems).
REFINE_NEVER, REFINE_ON_CANCELLATION, REFINE_ALWAYS = 0, 1, 2
#: |S_aa| below this fraction of |D_aa| + |(C^T A^-1 B)_aa| is cancellation.
CANCELLATION = 1e-6


@njit(cache=True, nogil=True)
def needs_refinement(policy, S, terms):
    """Whether a bordered solve with Schur complement S (k, k) takes a refinement step under
    ``policy`` (a ``REFINE_*``); ``terms`` (k, k) is |D| + |C^T A^-1 B| entrywise."""
    if policy == REFINE_ALWAYS:
        return True
    if policy == REFINE_NEVER:
        return False
    for a in range(S.shape[0]):
        if abs(S[a, a]) < CANCELLATION * terms[a, a]:
            return True
    return False
