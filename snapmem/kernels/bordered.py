"""Band matrices bordered by a few dense rows and columns (rigid bodies' own degrees of freedom).

    K = [[A, B], [B^T, C]]     A: n_b x n_b band, B: n_b x k dense, C: k x k

A rigid body on the axis (a ball) touches many nodes, so its degree of freedom couples to all of
them: one dense row and column per body. Solves go by block elimination on the band LU of A
(the Schur complement S = C - B^T A^-1 B is k x k), so they stay O(n_b b^2 + n_b k); inertia
follows from Haynsworth's formula In(K) = In(A) + In(S). The interface is that of
:class:`~snapmem.kernels.banded.BandedMatrix` (factor().solve, matvec, to_dense, n, smallest_eigenvalues,
negative_count), so Newton, continuation and time stepping take either.

:func:`bordered_solve` is the same block elimination compiled, on the lower band and its LDL^T,
for the compiled time step; its refinement policy is an argument, as :meth:`BodyMatrix.factor`'s.
"""

from __future__ import annotations

import numpy as np
from snapmem._lazy import njit
import snapmem._lazy as _lazy

eigh = _lazy.function("scipy.linalg", "eigh")      # scipy.linalg: imported at first use

from snapmem.kernels.banded import LDLT_GROWTH_LIMIT, BandedMatrix, BorderedMatrix
from snapmem.kernels.linalg import _ldlt_solve_vector, band_ldlt, band_ldlt_solve, band_matvec, needs_refinement


class BodyMatrix(BorderedMatrix):
    """Symmetric [[A, B], [B^T, C]] with A a :class:`BandedMatrix`: the stiffness of a scene with
    rigid bodies. Solves are :class:`~snapmem.kernels.banded.BorderedMatrix`'s (block elimination with
    refinement); this class adds what stability checks and time stepping need.

    Parameters
    ----------
    band : BandedMatrix
        A, order n_b.
    border : ndarray (n_b, k)
        B.
    corner : ndarray (k, k)
        C.
    """

    def __init__(self, band: BandedMatrix, border: np.ndarray, corner: np.ndarray):
        super().__init__(band, border, border, corner)

    @property
    def band(self) -> BandedMatrix:
        return self.A

    @property
    def border(self) -> np.ndarray:
        return self.B

    @property
    def corner(self) -> np.ndarray:
        return self.D

    @property
    def b(self) -> int:
        return self.A.b

    def add_diagonal(self, d: np.ndarray) -> None:
        """K += diag(d) in place, d of shape (n,)."""
        nb = self.A.n
        self.A.add_diagonal(d[:nb])
        self.D = self.D + np.diag(d[nb:])

    def schur(self) -> np.ndarray:
        """S = C - B^T A^-1 B, shape (k, k)."""
        return self.D - self.B.T @ self.A.factor().solve(np.asfortranarray(self.B))

    def smallest_eigenvalues(self, k: int) -> np.ndarray:
        """The k smallest eigenvalues, ascending (dense: O(n^3), for the few scenes with bodies)."""
        k = min(k, self.n)
        return eigh(self.to_dense(), eigvals_only=True, subset_by_index=(0, k - 1), check_finite=False)

    def negative_count(self) -> int:
        """Number of negative eigenvalues: In(A) + In(S) (Haynsworth), O(n b^2)."""
        return self.A.negative_count() + int(np.count_nonzero(np.linalg.eigvalsh(self.schur()) < 0))


# ----------------------------------------------------------------------------------------------
# the compiled bordered solve

@njit(cache=True, nogil=True)
def _small_solve(S, g):
    """S^-1 g for the bodies' small k x k Schur complement: Gaussian elimination with partial
    pivoting (numba's np.linalg.solve is slow to compile for what is a 2 x 2 at most)."""
    k = g.size
    A, x = S.copy(), g.copy()
    for c in range(k):
        p = c
        for i in range(c + 1, k):
            if abs(A[i, c]) > abs(A[p, c]):
                p = i
        for j in range(k):
            A[c, j], A[p, j] = A[p, j], A[c, j]
        x[c], x[p] = x[p], x[c]
        for i in range(c + 1, k):
            f = A[i, c] / A[c, c]
            for j in range(c, k):
                A[i, j] -= f * A[c, j]
            x[i] -= f * x[c]
    for c in range(k - 1, -1, -1):
        for j in range(c + 1, k):
            x[c] -= A[c, j] * x[j]
        x[c] /= A[c, c]
    return x


@njit(cache=True, nogil=True)
def _eliminate(F, border, Z, S, rhs):
    """Block elimination of [[A, B], [B^T, C]] x = rhs with A = L D L^T (factors F), Z = A^-1 B (its
    first k columns), S the Schur."""
    nb, k = F.shape[0], border.shape[0]
    x = rhs.copy()
    _ldlt_solve_vector(F, x[:nb])
    if k == 0:
        return x
    g = np.empty(k)
    for a in range(k):
        g[a] = rhs[nb + a]
        for i in range(nb):
            g[a] -= border[a, i] * x[i]
    mu = g / S[0, 0] if k == 1 else _small_solve(S, g)
    for a in range(k):
        for i in range(nb):
            x[i] -= Z[i, a] * mu[a]
        x[nb + a] = mu[a]
    return x


@njit(cache=True, nogil=True, inline="always")
def band_solve(lower, rhs):
    """Solve A x = rhs for the band ``lower`` alone by its LDL^T: (x, ok), ok False for a tangent the
    LDL^T cannot take (as :func:`bordered_solve`, which this is without bodies; its own kernel, so
    that a scene without bodies compiles none of the bodies' elimination)."""
    F, negative, zero, growth = band_ldlt(lower, lower.shape[0] - 1)
    if zero > 0 or growth > LDLT_GROWTH_LIMIT:
        return rhs, False
    x = rhs.copy()
    _ldlt_solve_vector(F, x)
    return x, True


@njit(cache=True, nogil=True)
def bordered_solve(lower, border, corner, rhs, refine):
    """Solve [[A, B], [B^T, C]] x = rhs (A the band ``lower``, B = border^T) with the refinement
    policy ``refine`` (a ``REFINE_*`` of snapmem.kernels.linalg): (x, ok), ok False for a tangent
    the LDL^T cannot take (zero pivot, growth beyond LDLT_GROWTH_LIMIT of snapmem.kernels.banded)
    or a singular Schur complement.

    Block elimination, with A^-1 B and A^-1 rhs in one pass over the factors. Continuation
    refines always (at a fold A is singular and S = C - B^T A^-1 B a small difference of large
    terms); a time step, whose A includes M / h^2 and whose LDL^T's growth is bounded, needs it
    only where S shows that cancellation (REFINE_ON_CANCELLATION).
    """
    nb, k = lower.shape[1], border.shape[0]
    if k == 0:
        return band_solve(lower, rhs)
    F, negative, zero, growth = band_ldlt(lower, lower.shape[0] - 1)
    if zero > 0 or growth > LDLT_GROWTH_LIMIT:
        return rhs, False
    W = np.empty((nb, k + 1))
    for i in range(nb):
        for a in range(k):
            W[i, a] = border[a, i]
        W[i, k] = rhs[i]
    band_ldlt_solve(F, W)                             # [Z | y] = A^-1 [B | rhs_band]; Z is W[:, :k]
    S = np.empty((k, k))                              # corner - B^T Z, and |corner| + |B^T Z| (loops, not
    terms = np.empty((k, k))                          # copies and array expressions: each is an allocation)
    g = np.empty(k)
    for a in range(k):
        t = rhs[nb + a]
        for i in range(nb):
            t -= border[a, i] * W[i, k]
        g[a] = t
        for b in range(k):
            t = 0.0
            for i in range(nb):
                t += border[a, i] * W[i, b]
            S[a, b] = corner[a, b] - t
            terms[a, b] = abs(corner[a, b]) + abs(t)
            if not np.isfinite(S[a, b]):
                return rhs, False
    if k == 1 and S[0, 0] == 0.0:
        return rhs, False
    if k == 1:
        mu = g
        mu[0] = g[0] / S[0, 0]
    else:
        mu = _small_solve(S, g)
    x = np.empty(nb + k)
    for i in range(nb):
        t = W[i, k]
        for a in range(k):
            t -= W[i, a] * mu[a]
        x[i] = t
    for a in range(k):                                # (a loop: a slice assignment compiles a shape check)
        x[nb + a] = mu[a]
    if not needs_refinement(refine, S, terms):
        return x, True
    r = rhs.copy()                                    # one refinement step, r = rhs - M x
    Ax = band_matvec(lower, np.ascontiguousarray(x[:nb]).reshape(nb, 1))
    for i in range(nb):
        r[i] -= Ax[i, 0]
        for a in range(k):
            r[i] -= border[a, i] * x[nb + a]
    for a in range(k):
        for i in range(nb):
            r[nb + a] -= border[a, i] * x[i]
        for b in range(k):
            r[nb + a] -= corner[a, b] * x[nb + b]
    return x + _eliminate(F, border, W, S, r), True
