"""Band matrices bordered by a few dense rows and columns (rigid bodies' own degrees of freedom).

    K = [[A, B], [B^T, C]]     A: n_b x n_b band, B: n_b x k dense, C: k x k

A rigid body on the axis (a ball) touches many nodes, so its degree of freedom couples to all of
them: one dense row and column per body. Solves go by block elimination on the band LU of A
(the Schur complement S = C - B^T A^-1 B is k x k), so they stay O(n_b b^2 + n_b k); inertia
follows from Haynsworth's formula In(K) = In(A) + In(S). The interface is that of
:class:`~snapmem.kernels.banded.BandedMatrix` (lu().solve, matvec, to_dense, n, smallest_eigenvalues,
negative_count), so Newton, continuation and time stepping take either.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import eigh

from snapmem.kernels.banded import BandedMatrix, BorderedMatrix


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
        return self.D - self.B.T @ self.A.lu().solve(np.asfortranarray(self.B))

    def smallest_eigenvalues(self, k: int) -> np.ndarray:
        """The k smallest eigenvalues, ascending (dense: O(n^3), for the few scenes with bodies)."""
        k = min(k, self.n)
        return eigh(self.to_dense(), eigvals_only=True, subset_by_index=(0, k - 1), check_finite=False)

    def negative_count(self, known: np.ndarray | None = None) -> int:
        """Number of negative eigenvalues: In(A) + In(S) (Haynsworth), O(n b^2)."""
        if known is not None and (known.size == self.n or known[-1] >= 0):
            return int(np.count_nonzero(known < 0))
        return self.A.negative_count() + int(np.count_nonzero(np.linalg.eigvalsh(self.schur()) < 0))
