"""Symmetric banded matrices in LAPACK general-band storage, their LU solves and eigenvalues.

A matrix K of order n and half-bandwidth b is stored as ``ab`` of shape (3b + 1, n) with
K[i, j] = ab[2b + i - j, j]; the first b rows are the workspace LAPACK's ``gbtrf`` needs for
partial pivoting, so assembly writes straight into the array that is factorised (no copy into
another layout). Partial pivoting handles the indefinite K of unstable branches; Cholesky would not.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import eig_banded
from scipy.linalg.lapack import dgbtrf, dgbtrs


class BandedMatrix:
    """Square symmetric band matrix in general-band storage (see module docstring).

    Parameters
    ----------
    ab : ndarray, shape (3b + 1, n)
        Band storage; rows 0..b-1 are LU workspace and are ignored on input.
    b : int
        Half-bandwidth.
    """

    def __init__(self, ab: np.ndarray, b: int):
        self.ab = ab
        self.b = b

    @property
    def n(self) -> int:
        return self.ab.shape[1]

    @classmethod
    def from_dense(cls, K: np.ndarray, b: int) -> "BandedMatrix":
        """Band storage of a dense matrix (entries outside the band are dropped)."""
        n = K.shape[0]
        ab = np.zeros((3 * b + 1, n), order="F")
        for d in range(-b, b + 1):          # d = i - j
            diag = np.diagonal(K, -d)
            if d >= 0:
                ab[2 * b + d, : n - d] = diag
            else:
                ab[2 * b + d, -d:] = diag
        return cls(ab, b)

    def to_dense(self) -> np.ndarray:
        n, b = self.n, self.b
        K = np.zeros((n, n))
        for d in range(-b, b + 1):
            i = np.arange(max(0, d), min(n, n + d))
            K[i, i - d] = self.ab[2 * b + d, i - d]
        return K

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """K @ x for x of shape (n,)."""
        n, b = self.n, self.b
        y = self.ab[2 * b] * x
        for d in range(1, b + 1):
            y[d:] += self.ab[2 * b + d, : n - d] * x[: n - d]      # below the diagonal
            y[: n - d] += self.ab[2 * b - d, d:] * x[d:]           # above
        return y

    def lower(self) -> np.ndarray:
        """Lower symmetric band form (b + 1, n) as ``scipy.linalg.eig_banded`` takes it."""
        return self.ab[2 * self.b:]

    def lu(self) -> "BandedLU":
        """LU factorisation with partial pivoting (LAPACK dgbtrf) of a copy of this matrix."""
        lu, piv, info = dgbtrf(self.ab, self.b, self.b)
        return BandedLU(lu, piv, self.b, singular=info > 0)

    def smallest_eigenvalues(self, k: int) -> np.ndarray:
        """The k smallest eigenvalues, ascending (O(n b^2): band reduction then bisection)."""
        k = min(k, self.n)
        return eig_banded(self.lower(), lower=True, eigvals_only=True, select="i",
                          select_range=(0, k - 1), check_finite=False)

    def negative_count(self, known: np.ndarray | None = None) -> int:
        """Number of negative eigenvalues (the inertia index).

        ``known`` are the smallest eigenvalues already computed; only if all of them are
        negative is the full count computed by bisection on (-inf, 0).
        """
        if known is not None and (known.size == self.n or known[-1] >= 0):
            return int(np.count_nonzero(known < 0))
        neg = eig_banded(self.lower(), lower=True, eigvals_only=True, select="v",
                         select_range=(-np.inf, 0.0), check_finite=False)
        return int(neg.size)


class BandedLU:
    """An LU factorisation of a :class:`BandedMatrix`; ``solve`` takes one or several right-hand sides."""

    def __init__(self, lu, piv, b, singular: bool):
        self._lu, self._piv, self.b, self.singular = lu, piv, b, singular

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve K x = rhs for rhs of shape (n,) or (n, k)."""
        x, info = dgbtrs(self._lu, self.b, self.b, rhs, self._piv)
        return x


class BorderedMatrix:
    """The matrix [[A, B], [C^T, D]] with A banded (or itself bordered) and k border rows/columns.

    Continuation's extended systems have this shape (A = K, B = dR/dlambda, C = the tangent), as
    does volume control (B = C = grad V). Solved by block elimination with one step of iterative
    refinement (BEMW, Govaerts & Pryce 1990), which stays accurate when A is singular but the
    whole matrix is not: at a fold K is singular and the arclength system is regular.

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
        top = self.A.matvec(x[:n]) + self.B @ x[n:]
        return np.concatenate([top, self.C.T @ x[:n] + self.D @ x[n:]])

    def to_dense(self) -> np.ndarray:
        return np.block([[self.A.to_dense(), self.B], [self.C.T, self.D]])

    def lu(self) -> "BorderedLU":
        return BorderedLU(self)


class BorderedLU:
    """Factorisation of a :class:`BorderedMatrix`: LU of A and the k x k Schur complement."""

    def __init__(self, M: BorderedMatrix):
        self.M = M
        self.inner = M.A.lu()
        self.Z = self.inner.solve(M.B)                   # A^-1 B, (n, k)
        self.S = M.D - M.C.T @ self.Z                      # Schur complement (k, k)
        self.singular = bool(self.inner.singular or not np.all(np.isfinite(self.S))
                             or abs(np.linalg.det(self.S)) == 0.0)

    def _eliminate(self, rhs):
        n = self.M.A.n
        f, g = rhs[:n], rhs[n:]
        y = self.inner.solve(f)
        mu = np.linalg.solve(self.S, g - self.M.C.T @ y)
        return np.concatenate([y - self.Z @ mu, mu])

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve M x = rhs (rhs of shape (n,) or (n, m)); one refinement step."""
        x = self._eliminate(rhs)
        return x + self._eliminate(rhs - self.M.matvec(x))
