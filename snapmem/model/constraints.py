"""Linear constraints on a scene's nodes, held by a Lagrange multiplier.

A free membrane (a sphere held by nothing) can translate along the axis: every stiffness is
singular. Holding one node's z removes the translation but breaks the mesh's up-down symmetry.
:class:`CentreOfMassHeight` removes it without holding a node: the mass-weighted mean height of
the nodes keeps its reference value,

    g(q) = sum_i a_i (z_i - z_bar_i) = 0,    a_i = A_i / sum_j A_j   (A_i the ring areas),

by the Lagrangian term k mu g(q), with mu the multiplier (one more degree of freedom, carried
as a massless :class:`Multiplier` "body" after the node coordinates) and k a stiffness scale
[N/m] that makes the multiplier a length and its equation a force. The stiffness of the scene
is then the saddle matrix [[K, k a], [k a^T, 0]], banded and bordered by one dense row and
column (snapmem.kernels.bordered.BodyMatrix), solved by block elimination as every bordered
system is; statics, continuation and time stepping take it unchanged.

Stability is that of K on the constraint's tangent space (a^T dz = 0). By Haynsworth's inertia
formula the saddle matrix has exactly one negative eigenvalue more than that restriction, so a
stability count subtracts one per multiplier (:func:`multiplier_count`).

On a reference symmetric about z = 0 (the sphere) the weights are symmetric too, so the
constrained problem keeps the mesh's reflection symmetry: modes odd in z (the sphere's P_1,
P_3, ...) cannot couple to the load.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from snapmem.errors import SnapmemError, check_real
from snapmem.model.terms import NodeLocal, NodeTerm, RigidBody


@dataclass(frozen=True)
class Multiplier(RigidBody):
    """A Lagrange multiplier carried as a massless body degree of freedom (its ``z0`` is 0).
    Its value times the constraint's stiffness scale is the constraint's reaction [N]."""


def multiplier_count(scene) -> int:
    """The number of Lagrange multipliers among a scene's body degrees of freedom (each adds one
    negative eigenvalue to the saddle stiffness)."""
    return sum(1 for b in scene.bodies if isinstance(b, Multiplier))


@dataclass(frozen=True, eq=False)
class CentreOfMassHeight(NodeTerm):
    """The constraint that the area-weighted mean height of the nodes keeps its reference value.

    Parameters
    ----------
    z_reference : ndarray (N,)
        Reference heights z_bar_i of the nodes [m].
    area : ndarray (N,)
        Weight of each node, its reference ring area A_i [m^2] (a pole: its cap's); only the
        ratios matter.
    stiffness : float
        Scale k of the multiplier's coupling [N/m] (e.g. mu H): the multiplier is then a length
        [m] and the constraint's equation a force [N].
    name : str
        Name of the multiplier's degree of freedom in outputs.
    """

    z_reference: np.ndarray
    area: np.ndarray
    stiffness: float
    name: str = "support"

    def __post_init__(self):
        check_real("stiffness", self.stiffness, minimum=0.0, min_inclusive=False)
        area = np.asarray(self.area, float)
        z = np.asarray(self.z_reference, float)
        if area.shape != z.shape or area.ndim != 1 or np.any(area < 0) or area.sum() <= 0:
            raise SnapmemError(f"area: must be non-negative weights, one per node ({z.size}), not all zero")
        object.__setattr__(self, "_weights", area / area.sum())
        object.__setattr__(self, "_z_reference", z.copy())
        object.__setattr__(self, "bodies", (Multiplier(self.name, 0.0, 0.0),))

    @property
    def weights(self) -> np.ndarray:
        """a_i, shape (N,), summing to 1."""
        return self._weights

    def violation(self, x: np.ndarray) -> float:
        """g = sum_i a_i (z_i - z_bar_i) of node positions x (N, 2) [m]."""
        return float(self._weights @ (x[:, 1] - self._z_reference))

    def node_local(self, x, y, area, loads, order) -> NodeLocal:
        k, a = self.stiffness, self._weights
        mu = float(y[0])
        out = NodeLocal(k * mu * self.violation(x))
        if order >= 1:
            g = np.zeros((a.size, 3))
            g[:, 1] = k * mu * a
            g[:, 2] = k * a * (x[:, 1] - self._z_reference)
            out.gradient = g
        if order >= 2:
            h = np.zeros((a.size, 3, 3))
            h[:, 1, 2] = h[:, 2, 1] = k * a
            out.hessian = h
        return out

    def __repr__(self):
        return f"CentreOfMassHeight(nodes={self._weights.size}, stiffness={self.stiffness:g})"
