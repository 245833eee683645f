"""Symmetric banded matrices stored as their lower band, their solves and eigenvalues.

A matrix K of order n and half-bandwidth b is stored as ``lower`` of shape (b + 1, n) with
K[i, j] = lower[i - j, j] for 0 <= i - j <= b: assembly writes only these entries, a third of
LAPACK's general-band storage for b = 3 (why that matters: docs/performance.md). Solves
factorise K as L D L^T without pivoting (a compiled kernel on the lower band) wherever that is
stable: its element growth is measured and, if large (a small pivot inside an indefinite K,
which Cholesky could not factor at all) or a pivot is zero, LAPACK's band LU with partial
pivoting is used instead, on the general-band storage built for it.
"""

from __future__ import annotations

import numpy as np
import snapmem._lazy as _lazy

eig_banded = _lazy.function("scipy.linalg", "eig_banded")        # scipy.linalg: imported at first use
dgbtrf = _lazy.function("scipy.linalg.lapack", "dgbtrf")
dgbtrs = _lazy.function("scipy.linalg.lapack", "dgbtrs")

from snapmem.kernels.linalg import (REFINE_ALWAYS, band_ldlt, band_ldlt_solve, band_matvec, needs_refinement,
                                   orthonormal, ritz_step)

#: Largest element growth of the LDL^T factors (``snapmem.kernels.band_ldlt``: 1 for a positive
#: definite K) at which they are used for solves; beyond it the pivoted band LU is. At 1e3 the
#: solve's backward error is at most about 1e3 eps |K|, no worse than LU's own bound for b = 5.
LDLT_GROWTH_LIMIT = 1e3


class BandedMatrix:
    """Square symmetric band matrix, stored as its lower band (see module docstring).

    Parameters
    ----------
    ab : ndarray, shape (3b + 1, n)
        General-band storage, K[i, j] = ab[2b + i - j, j]; only its lower band (rows 2b..3b)
        is kept, as a view. Assembly builds the lower band directly: :meth:`from_lower`.
    b : int
        Half-bandwidth.
    """

    def __init__(self, ab: np.ndarray, b: int):
        self.b = b
        self._lower = ab[2 * b:]

    @classmethod
    def from_lower(cls, lower: np.ndarray, b: int) -> "BandedMatrix":
        """The matrix whose lower band is ``lower`` (b + 1, n): lower[i - j, j] = K[i, j] (no copy)."""
        M = cls.__new__(cls)
        M.b, M._lower = b, lower
        return M

    @property
    def n(self) -> int:
        return self._lower.shape[1]

    @property
    def ab(self) -> np.ndarray:
        """General-band storage (3b + 1, n) of both triangles, Fortran order, built on demand (a new
        array: LAPACK's pivoted LU and the benchmark's dgbsv take it)."""
        n, b, lower = self.n, self.b, self._lower
        ab = np.zeros((3 * b + 1, n), order="F")
        ab[2 * b:] = lower
        for d in range(1, b + 1):                       # K[j - d, j] = K[j, j - d] = lower[d, j - d]
            ab[2 * b - d, d:] = lower[d, : n - d]
        return ab

    @classmethod
    def from_dense(cls, K: np.ndarray, b: int) -> "BandedMatrix":
        """Band storage of a symmetric dense matrix (its lower band; entries outside it are dropped)."""
        n = K.shape[0]
        lower = np.zeros((b + 1, n))
        for d in range(b + 1):
            lower[d, : n - d] = np.diagonal(K, -d)
        return cls.from_lower(lower, b)

    def to_dense(self) -> np.ndarray:
        n, b = self.n, self.b
        K = np.zeros((n, n))
        for d in range(b + 1):
            i = np.arange(d, n)
            K[i, i - d] = K[i - d, i] = self._lower[d, : n - d]
        return K

    def add_diagonal(self, d: np.ndarray) -> None:
        """K += diag(d) in place, d of shape (n,)."""
        self._lower[0] += d

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """K @ x for x of shape (n,) or (n, m) (from the lower band: K is symmetric)."""
        x = np.asarray(x, dtype=float)
        return band_matvec(self._lower, np.ascontiguousarray(x.reshape(x.shape[0], -1))).reshape(x.shape)

    def lower(self) -> np.ndarray:
        """Lower symmetric band form (b + 1, n) as ``scipy.linalg.eig_banded`` takes it (the storage itself)."""
        return self._lower

    def factor(self):
        """A factorisation for solves, with the inertia: :class:`BandedLDLT` where it is stable
        (no zero pivot, growth at most :data:`LDLT_GROWTH_LIMIT`), else :meth:`pivoted_lu`."""
        F, negative, zero, growth = band_ldlt(self.lower(), self.b)
        if zero == 0 and growth <= LDLT_GROWTH_LIMIT:
            return BandedLDLT(F, negative)
        return self.pivoted_lu(negative)

    #: The former name of :meth:`factor` (which is mostly an LDL^T, not an LU), kept for callers outside the package.
    lu = factor

    def pivoted_lu(self, negative: int | None = None) -> "BandedLU":
        """LU factorisation with partial pivoting (LAPACK dgbtrf) of this matrix in general-band storage."""
        lu, piv, info = dgbtrf(self.ab, self.b, self.b)
        return BandedLU(lu, piv, self.b, singular=info > 0,
                        negative=self.negative_count() if negative is None else negative)

    def smallest_eigenvalues(self, k: int) -> np.ndarray:
        """The k smallest eigenvalues, ascending, exactly (LAPACK band reduction: O(n^2 b) work,
        so a reference for tests and small problems; solvers use :meth:`eigenvalues_near_zero`)."""
        k = min(k, self.n)
        return eig_banded(self.lower(), lower=True, eigvals_only=True, select="i",
                          select_range=(0, k - 1), check_finite=False)

    def eigenvalues_near_zero(self, k: int, start: np.ndarray | None = None, lu=None, tol: float = 1e-13,
                              max_iterations: int = 40):
        """The k eigenvalues of smallest magnitude, ascending, and their vectors: O(n b^2).

        See :func:`eigenvalues_near_zero`.
        """
        return eigenvalues_near_zero(self, k, start, lu, tol, max_iterations=max_iterations)

    def negative_count(self) -> int:
        """Number of negative eigenvalues (the inertia index), from the pivot signs of a band
        LDL^T factorisation (Sylvester): O(n b^2)."""
        return int(band_ldlt(self.lower(), self.b)[1])


class BandedLDLT:
    """The L D L^T factors of a :class:`BandedMatrix` (``snapmem.kernels.band_ldlt``); ``solve``
    takes one or several right-hand sides; ``negative`` is the inertia index of the matrix."""

    singular = False

    def __init__(self, F: np.ndarray, negative: int):
        self._F, self.negative = F, int(negative)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve K x = rhs for rhs of shape (n,) or (n, k)."""
        x = np.array(rhs, dtype=float, order="C")
        band_ldlt_solve(self._F, x.reshape(x.shape[0], -1))
        return x


class BandedLU:
    """An LU factorisation of a :class:`BandedMatrix`; ``solve`` takes one or several right-hand
    sides; ``negative`` is the inertia index of the matrix (from LDL^T pivot signs)."""

    def __init__(self, lu, piv, b, singular: bool, negative: int):
        self._lu, self._piv, self.b, self.singular, self.negative = lu, piv, b, singular, int(negative)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve K x = rhs for rhs of shape (n,) or (n, k)."""
        x, info = dgbtrs(self._lu, self.b, self.b, rhs, self._piv)
        return x


class BorderedMatrix:
    """The matrix [[A, B], [C^T, D]] with A banded (or itself bordered) and k border rows/columns.

    Continuation's extended systems have this shape (A = K, B = dR/dlambda, C = the tangent), as
    does volume control (B = C = grad V). Solved by block elimination with one step of iterative
    refinement (BEMW, Govaerts & Pryce 1990), which stays accurate when A is singular but the
    whole matrix is not: at a fold K is singular and the arclength system is regular. The
    refinement policy is an argument of :meth:`factor` (:data:`snapmem.kernels.linalg.REFINE_ALWAYS`
    by default; the compiled bordered solve, :func:`snapmem.kernels.bordered.bordered_solve`,
    takes the same policies).

    Parameters
    ----------
    A : BandedMatrix or BorderedMatrix, order n
    B, C : ndarray, shape (n, k)
    D : ndarray, shape (k, k)
    """

    def __init__(self, A, B, C, D):
        self.A = A
        self.B = np.asarray(B, dtype=float).reshape(A.n, -1)
        self.C = np.asarray(C, dtype=float).reshape(A.n, -1)
        self.D = np.asarray(D, dtype=float).reshape(self.B.shape[1], self.B.shape[1])

    @property
    def n(self) -> int:
        return self.A.n + self.D.shape[0]

    def matvec(self, x: np.ndarray) -> np.ndarray:
        n = self.A.n
        if x.ndim == 2:
            return np.stack([self.matvec(col) for col in x.T], axis=1)
        y = np.empty(self.n)
        y[:n] = self.A.matvec(x[:n])
        y[:n] += self.B @ x[n:]
        y[n:] = self.C.T @ x[:n] + self.D @ x[n:]
        return y

    def to_dense(self) -> np.ndarray:
        return np.block([[self.A.to_dense(), self.B], [self.C.T, self.D]])

    def factor(self, inner=None, refine: int = REFINE_ALWAYS) -> "BorderedLU":
        """Block factorisation; ``inner``, a factorisation of A already made, is reused; ``refine``
        is the refinement policy of its solves (a ``REFINE_*`` of :mod:`snapmem.kernels.linalg`)."""
        return BorderedLU(self, inner, refine)

    #: The former name of :meth:`factor`, kept for callers outside the package.
    lu = factor

    def eigenvalues_near_zero(self, k: int, start: np.ndarray | None = None, lu=None, tol: float = 1e-13,
                              max_iterations: int = 40):
        """As :meth:`BandedMatrix.eigenvalues_near_zero` (for a symmetric bordering)."""
        return eigenvalues_near_zero(self, k, start, lu, tol, max_iterations=max_iterations)


class BorderedLU:
    """Factorisation of a :class:`BorderedMatrix`: a factorisation of A and the k x k Schur
    complement; ``refine`` is the refinement policy of :meth:`solve` (a ``REFINE_*`` of
    :mod:`snapmem.kernels.linalg`)."""

    def __init__(self, M: BorderedMatrix, inner=None, refine: int = REFINE_ALWAYS):
        self.M = M
        self.inner = M.A.factor() if inner is None else inner
        self.Z = self.inner.solve(M.B)                   # A^-1 B, (n, k)
        self.S = M.D - M.C.T @ self.Z                      # Schur complement (k, k)
        self.refine = refine
        self.singular = bool(self.inner.singular or not np.all(np.isfinite(self.S))
                             or (self.S.shape == (1, 1) and self.S[0, 0] == 0.0))

    def _eliminate(self, rhs):
        n = self.M.A.n
        y = self.inner.solve(rhs[:n])
        g = rhs[n:] - self.M.C.T @ y
        mu = g / self.S[0, 0] if self.S.shape == (1, 1) else np.linalg.solve(self.S, g)
        x = np.empty(rhs.shape)
        x[:n] = y - self.Z @ mu
        x[n:] = mu
        return x

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve M x = rhs (rhs of shape (n,) or (n, m)), with one refinement step where the policy asks for it."""
        x = self._eliminate(rhs)
        if self.refine != REFINE_ALWAYS and not needs_refinement(self.refine, self.S, self._terms()):
            return x
        return x + self._eliminate(rhs - self.M.matvec(x))

    def _terms(self) -> np.ndarray:
        """|D| + |C^T Z| entrywise: the size of the terms whose difference is the Schur complement."""
        return np.abs(self.M.D) + np.abs(self.M.C.T @ self.Z)


def eigenvalues_near_zero(M, k: int, start: np.ndarray | None = None, lu=None, tol: float = 1e-13,
                          tol_others: float = 1e-10, max_iterations: int = 40, subspace: bool = False):
    """The k eigenvalues of a symmetric matrix nearest zero, ascending, with their eigenvectors.

    Inverse subspace iteration on the factorisation (M needs ``factor()`` and ``n``; ``lu``, one
    already made, is reused), with four guard vectors: each iteration is one solve with k + 4
    right-hand sides, so the cost is O(n b^2). Rayleigh-Ritz is done on K^-1 (H = V^T K^-1 V uses
    the solve just made, no product with K; a compiled kernel), and an iteration stops when the
    Ritz value nearest zero moves by less than ``tol`` |K| (the others by less than
    ``tol_others`` |K|) or stops improving (rounding). Warm-started from ``start`` (the vectors,
    or the whole subspace, of a nearby state) it converges in two or three iterations.

    Returns
    -------
    values : ndarray (k,)
    vectors : ndarray (n, k)
    subspace : ndarray (n, k + 4), only if ``subspace``: the last iterate, to warm-start the next state
    """
    n = M.n
    k = min(k, n)
    m = min(n, k + 4)
    filled = 0 if start is None else min(m, np.asarray(start).reshape(n, -1).shape[1])
    V = np.empty((n, m))
    if filled < m:
        V[:, filled:] = np.random.default_rng(7).normal(size=(n, m))[:, filled:]
    if filled:
        V[:, :filled] = np.asarray(start).reshape(n, -1)[:, :filled]
    if lu is None:
        lu = M.factor()
    if lu.singular:
        raise np.linalg.LinAlgError("matrix is exactly singular")
    V = orthonormal(V)
    scale = scale_of(M)
    theta = previous = None
    step = np.inf
    for _ in range(max_iterations):
        theta, V = ritz_step(V, np.ascontiguousarray(lu.solve(V)))     # W = K^-1 V
        if previous is not None:
            change = np.abs(theta[:k] - previous[:k])
            first_done = change[0] <= tol * scale or change[0] >= 0.5 * step    # converged, or at rounding
            step = change[0]
            if first_done and np.all(change[1:] <= tol_others * scale):
                break
        previous = theta
    ascending = np.argsort(theta[:k])
    values, vectors = theta[:k][ascending], V[:, :k][:, ascending]
    return (values, vectors, V) if subspace else (values, vectors)


def scale_of(M) -> float:
    """A size of the matrix: its largest diagonal entry in magnitude (band or bordered)."""
    inner = M
    while isinstance(inner, BorderedMatrix):
        inner = inner.A
    return float(np.max(np.abs(inner.ab[2 * inner.b]))) or 1.0
