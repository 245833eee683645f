"""Band matrices bordered by a few dense rows and columns (rigid bodies' own degrees of freedom).

    K = [[A, B], [B^T, C]]     A: n_b x n_b band, B: n_b x k dense, C: k x k

A rigid body on the axis (a ball) touches many nodes, so its degree of freedom couples to all of
them: one dense row and column per body. Solves go by block elimination on the band LU of A
(the Schur complement S = C - B^T A^-1 B is k x k), so they stay O(n_b b^2 + n_b k); inertia
follows from Haynsworth's formula In(K) = In(A) + In(S). The interface is that of
:class:`~snapmem.banded.BandedMatrix`, so Newton, continuation and time stepping take either.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import eigh, lu_factor, lu_solve

from .banded import BandedMatrix


class BorderedMatrix:
    """Symmetric [[A, B], [B^T, C]] with A a :class:`BandedMatrix`.

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
        self.band, self.border, self.corner = band, border, corner

    @property
    def n(self) -> int:
        return self.band.n + self.corner.shape[0]

    @property
    def b(self) -> int:
        return self.band.b

    def to_dense(self) -> np.ndarray:
        return np.block([[self.band.to_dense(), self.border], [self.border.T, self.corner]])

    def matvec(self, x: np.ndarray) -> np.ndarray:
        nb = self.band.n
        x1, x2 = x[:nb], x[nb:]
        return np.concatenate([self.band.matvec(x1) + self.border @ x2, self.border.T @ x1 + self.corner @ x2])

    def add_diagonal(self, d: np.ndarray) -> None:
        """K += diag(d) in place, d of shape (n,)."""
        nb = self.band.n
        self.band.ab[2 * self.band.b] += d[:nb]
        self.corner = self.corner + np.diag(d[nb:])

    def lu(self) -> "BorderedLU":
        """Band LU of A and dense LU of the Schur complement S = C - B^T A^-1 B."""
        lu_a = self.band.lu()
        if lu_a.singular:
            return BorderedLU(lu_a, None, None, self.border.shape[1], singular=True)
        x = lu_a.solve(np.asfortranarray(self.border))
        schur = self.corner - self.border.T @ x
        lu_s = lu_factor(schur, check_finite=False)
        singular = bool(np.any(np.abs(np.diag(lu_s[0])) <= 1e-14 * max(1.0, np.abs(schur).max())))
        return BorderedLU(lu_a, x, lu_s, self.border.shape[1], singular, self.border)

    def schur(self) -> np.ndarray:
        """S = C - B^T A^-1 B, shape (k, k)."""
        x = self.band.lu().solve(np.asfortranarray(self.border))
        return self.corner - self.border.T @ x

    def smallest_eigenvalues(self, k: int) -> np.ndarray:
        """The k smallest eigenvalues, ascending (dense: O(n^3), for the few scenes with bodies)."""
        k = min(k, self.n)
        return eigh(self.to_dense(), eigvals_only=True, subset_by_index=(0, k - 1), check_finite=False)

    def negative_count(self, known: np.ndarray | None = None) -> int:
        """Number of negative eigenvalues: In(A) + In(S) (Haynsworth), O(n b^2)."""
        if known is not None and (known.size == self.n or known[-1] >= 0):
            return int(np.count_nonzero(known < 0))
        return self.band.negative_count() + int(np.count_nonzero(np.linalg.eigvalsh(self.schur()) < 0))


class BorderedLU:
    """Block-elimination solver of a :class:`BorderedMatrix`; ``solve`` takes (n,) or (n, k)."""

    def __init__(self, lu_a, x, lu_s, k, singular, border=None):
        self._lu_a, self._x, self._lu_s, self.k, self.singular, self._border = lu_a, x, lu_s, k, singular, border

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        nb = rhs.shape[0] - self.k
        r1, r2 = rhs[:nb], rhs[nb:]
        y1 = self._lu_a.solve(r1)
        x2 = lu_solve(self._lu_s, r2 - self._border.T @ y1, check_finite=False)
        return np.concatenate([y1 - self._x @ x2, x2], axis=0)
