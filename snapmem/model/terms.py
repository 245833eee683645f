"""Energy terms of a scene: each is a potential whose gradient is (minus) a force.

Two kinds, distinguished by what they give the scene's assembly:

* a **density term** gives an energy per unit reference volume W(lam1, lam2) with its
  derivatives (a :class:`~snapmem.model.materials.Density`); the scene sums the densities of all such
  terms and applies the chain rule to edge coordinates once (``edge_local``);
* an **edge term** gives its own per-edge energy, gradient (E, 4) and Hessian (E, 4, 4).

A term that depends on a load parameter (``pressure``, ``voltage``) names it in ``loads`` and
gives the derivative of its gradient with respect to that load, for continuation.

A term the compiled time step (snapmem.dynamics.compiled_step) can evaluate says so by its
``compiled`` method, which returns a *declaration* (one of the named tuples below: the numbers
the kernel needs) or None; a scene runs the compiled step when every one of its terms declares.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from snapmem.errors import check_real
from snapmem.kernels.assembly import swept_volume
from snapmem.kernels.laws import LAW_GENT, LAW_LINEAR, electric_density
from snapmem.model.kinematics import EdgeKinematics
from snapmem.model.materials import Density, Gent, InvariantLaw, Law
from snapmem.model.prestretch import Prestretched


# ----------------------------------------------------------------------------------------------
# declarations: what the compiled time step needs of a term
class LawDeclaration(NamedTuple):
    """A stretching law the kernel evaluates: its kind (snapmem.kernels.laws.LAW_*) and parameters,
    at the total stretch of the mounting's prestretches (meridional, hoop; 1, 1 stress-free)."""

    kind: int
    params: tuple
    prestretch: tuple = (1.0, 1.0)


class ViscousDeclaration(NamedTuple):
    """Viscous networks (snapmem.model.viscous.ViscousNetworks): the term itself, whose moduli, Gent
    locks and viscosities the kernel takes, and whose open step (h, zeta_hat) each solve reads."""

    term: object


class ElectricDeclaration(NamedTuple):
    """The electric term: its density is -coefficient voltage^2 lam1^2 lam2^2, coefficient = eps / (2 H^2)."""

    coefficient: float


class PressureDeclaration(NamedTuple):
    """The pressure work -p V (the swept volume, fused into the membrane assembly)."""


class LinearContactDeclaration(NamedTuple):
    """A barrier on a gap linear in one coordinate, d_i = sign x[i, axis] + offset (rod, shell, plane).

    nodes : (M,) the nodes that can touch; coef : (N,) kappa A_i / dhat of every node [Pa m]."""

    nodes: np.ndarray
    axis: int
    sign: float
    offset: float
    dhat: float
    coef: np.ndarray


class BallDeclaration(NamedTuple):
    """A ball on the axis touching edges: radius, barrier width, coef (E,) kappa A_e / dhat of every
    edge, start height z0, and its body: the index in q of its height (-1 if held) and its weight
    -m g [N] (0 if held)."""

    radius: float
    dhat: float
    coef: np.ndarray
    z0: float
    dof: int
    weight: float


class Term:
    """Base class: ``loads`` are the names of the load parameters the term depends on."""

    loads: tuple[str, ...] = ()

    def compiled(self, scene):
        """What the compiled time step needs of this term in ``scene`` (a declaration above), or
        None if it has no compiled form (then the scene runs the general path). A subclass that
        changes the energy must override this too."""
        return None


class DensityTerm(Term):
    """A term that is an energy density per unit reference volume, integrated over the membrane."""

    def density(self, kin: EdgeKinematics, loads) -> Density:
        raise NotImplementedError

    def load_density(self, kin: EdgeKinematics, loads, name: str) -> Density:
        """d(density)/d(load ``name``): only ``w1`` and ``w2`` are used."""
        raise NotImplementedError

    def admissible(self, kin: EdgeKinematics) -> np.ndarray:
        return np.ones(kin.l.shape, dtype=bool)

    @property
    def restricts_domain(self) -> bool:
        """Whether :meth:`admissible` can say no where stretches are positive; if not, the scene
        skips it (positive radii and lengths already make every stretch positive)."""
        return type(self).admissible is not DensityTerm.admissible


class EdgeTerm(Term):
    """A term that gives its energy directly per edge, in the edge's 4 coordinates."""

    def edge_local(self, kin: EdgeKinematics, loads, order: int):
        """Return (energy, gradient (E, 4) or None, Hessian (4, 4, E) or None) for order 0, 1, 2.

        The Hessian is entry-major: ``hess[i, j]`` is the (E,) vector of entry (i, j) of every
        edge's 4x4 block, so each entry is one contiguous array.
        """
        raise NotImplementedError

    def load_gradient(self, kin: EdgeKinematics, loads, name: str) -> np.ndarray:
        """d(gradient)/d(load ``name``), shape (E, 4)."""
        raise NotImplementedError


@dataclass(frozen=True)
class Stretching(DensityTerm):
    """Hyperelastic stretching energy of the membrane with strain energy density ``law``."""

    law: Law

    def density(self, kin, loads):
        return self.law.density(kin.lam1, kin.lam2)

    def admissible(self, kin):
        return self.law.admissible(kin.lam1, kin.lam2)

    @property
    def restricts_domain(self) -> bool:
        """Whether the law's domain is smaller than positive stretches (Gent's lock)."""
        return type(self.law).admissible is not Law.admissible

    def compiled(self, scene):
        """The law's kind: any law linear in the invariants (its constant dW/dI1, dW/dI2), or one
        of :data:`COMPILED_LAWS`, possibly mounted prestretched (its prestretches); None for another
        law (Yeoh)."""
        law = self.law
        if isinstance(law, Prestretched):
            inner = Stretching(law.law).compiled(scene)
            return None if inner is None else inner._replace(prestretch=(float(law.lp1), float(law.lp2)))
        if isinstance(law, InvariantLaw) and law.linear:
            return LawDeclaration(LAW_LINEAR, tuple(float(x) for x in law.invariant_derivatives(3.0, 3.0)[1:3]))
        declare = COMPILED_LAWS.get(type(law))
        return None if declare is None else declare(law)


#: Laws the compiled kernels evaluate beyond the linear ones: law class -> its declaration.
COMPILED_LAWS = {
    Gent: lambda law: LawDeclaration(LAW_GENT, (float(law.mu), float(law.Jlim))),
}


@dataclass(frozen=True)
class Electric(DensityTerm):
    """Electrostatic free energy at fixed voltage, W_el = -(eps/2) (phi/H)^2 lam1^2 lam2^2.

    The minus sign is the Legendre transform for a voltage held by a source: voltage softens
    the membrane (MODEL.md section 2).

    Attributes
    ----------
    permittivity : float
        eps [F/m], > 0.
    thickness : float
        Reference thickness H [m], > 0.
    """

    permittivity: float
    thickness: float
    loads = ("voltage",)

    def __post_init__(self):
        check_real("eps", self.permittivity, minimum=0.0, min_inclusive=False)
        check_real("H", self.thickness, minimum=0.0, min_inclusive=False)

    def _density(self, kin, a: float) -> Density:
        """Density of -a lam1^2 lam2^2 and its derivatives (snapmem.kernels.laws.electric_density)."""
        return Density(*electric_density.py_func(kin.lam1, kin.lam2, a))

    def density(self, kin, loads):
        phi = loads["voltage"]
        return self._density(kin, 0.5 * self.permittivity * (phi / self.thickness) ** 2)

    def load_density(self, kin, loads, name):
        assert name == "voltage"
        return self._density(kin, self.permittivity * loads["voltage"] / self.thickness ** 2)

    def compiled(self, scene):
        return ElectricDeclaration(0.5 * self.permittivity / self.thickness ** 2)


class PressureWork(EdgeTerm):
    """Work of the pressure difference p (inside minus outside) [Pa]: energy -p V(q).

    V is the exact volume swept by the polyline about the axis,
    V = sum over edges of (pi/3)(r_a^2 + r_a r_b + r_b^2)(z_b - z_a) [m^3],
    so the follower pressure force is a true gradient and its Jacobian is symmetric.
    """

    loads = ("pressure",)

    @staticmethod
    def volume_local(kin: EdgeKinematics, order: int, scale: float = 1.0):
        """Per-edge volume, its gradient (E, 4) and entry-major Hessian (4, 4, E) (None below ``order``).

        ``scale`` multiplies the gradient and Hessian (not the volume), so -p dV needs no copy.
        The formula is snapmem.kernels.assembly.swept_volume's.
        """
        dz = kin.dz
        v, c, s, ga, gb = swept_volume.py_func(kin.ra, kin.rb, dz, scale)
        if order < 1:
            return v, None, None
        grad = np.stack([ga * dz, -s, gb * dz, s], axis=1)
        if order < 2:
            return v, grad, None
        hess = np.zeros((4, 4, v.size))
        hess[0, 0] = hess[2, 2] = 2.0 * c * dz
        hess[0, 2] = hess[2, 0] = c * dz
        hess[0, 1] = hess[1, 0] = -ga
        hess[0, 3] = hess[3, 0] = ga
        hess[2, 1] = hess[1, 2] = -gb
        hess[2, 3] = hess[3, 2] = gb
        return v, grad, hess

    def edge_local(self, kin, loads, order):
        p = loads["pressure"]
        v, g, h = self.volume_local(kin, order, scale=-p)
        return -p * v.sum(), g, h

    def load_gradient(self, kin, loads, name):
        assert name == "pressure"
        return -self.volume_local(kin, 1)[1]

    def compiled(self, scene):
        return PressureDeclaration()


@dataclass(frozen=True)
class RigidBody:
    """A rigid body that moves along the axis: one degree of freedom, its height z.

    A term that couples nodes to a body lists it in its ``bodies``; the scene appends one
    degree of freedom per body after the 2N node coordinates.

    Attributes
    ----------
    name : str
        Name used in outputs (e.g. ``ball``).
    z0 : float
        Height of the body in the reference state [m].
    mass : float
        Mass [kg] (its inertia in dynamics).
    """

    name: str
    z0: float
    mass: float


@dataclass
class NodeLocal:
    """What a node term gives the assembly, for N nodes and k = len(term.bodies).

    Attributes
    ----------
    energy : float
        [J]
    nodes : ndarray (M,) of int or None
        The nodes ``gradient`` and ``hessian`` rows belong to (None: all N, in order); a
        barrier lists only the nodes within its width.
    gradient : ndarray (M, 2 + k) or None
        d(energy)/d(r_i, z_i, y_1..y_k) of each node's share [N].
    hessian : ndarray (M, 2 + k, 2 + k) or None
        Second derivatives of each node's share [N/m].
    body_gradient, body_hessian : ndarray (k,), (k, k) or None
        Parts that depend on the body coordinates y alone (a body's weight).
    edges : ndarray (M_e,) of int or None
        The edges ``edge_gradient`` and ``edge_hessian`` belong to (None: all E, in order).
    edge_gradient, edge_hessian : ndarray (M_e, 4 + k), (4 + k, 4 + k, M_e) or None
        Parts summed over edges instead (an edge's distance to a body), in each edge's local
        coordinates (r_a, z_a, r_b, z_b) followed by y; the Hessian entry-major like edge terms'.
    barrier_rounding : float
        A contact barrier's largest |Hessian entry| times the largest |coordinate| its gaps are
        computed from [N] (0 otherwise, or below order 2): eps times it is the noise the
        coordinates' round-off puts in its forces (snapmem.kernels.assembly.residual_floor).
    """

    energy: float
    nodes: np.ndarray | None = None
    gradient: np.ndarray | None = None
    hessian: np.ndarray | None = None
    body_gradient: np.ndarray | None = None
    body_hessian: np.ndarray | None = None
    edges: np.ndarray | None = None
    edge_gradient: np.ndarray | None = None
    edge_hessian: np.ndarray | None = None
    barrier_rounding: float = 0.0


class NodeTerm(Term):
    """A term summed over nodes (a contact barrier): node i's local coordinates are
    (r_i, z_i) followed by the heights y of the term's ``bodies``.

    ``area`` passed in is each node's reference ring area 2 pi r_bar_i l_bar_i (a pole node:
    its cap), shape (N,) [m^2].
    """

    bodies: tuple = ()

    def node_local(self, x: np.ndarray, y: np.ndarray, area: np.ndarray, loads, order: int) -> NodeLocal:
        raise NotImplementedError

    def admissible(self, x: np.ndarray, y: np.ndarray) -> str | None:
        """Why (x (N, 2), y (k,)) is outside this term's domain (a gap <= 0), or None."""
        return None

    def max_step(self, x, y, dx, dy) -> float:
        """Largest fraction alpha <= 1 of the step (dx, dy) that keeps the state admissible."""
        return 1.0

    def compiled(self, scene, bodies: slice = slice(0, 0)):
        """As :meth:`Term.compiled`; ``bodies`` is where this term's body coordinates are in q."""
        return None


#: Every energy term with a factory of one example instance for a membrane of thickness H,
#: so that a single test checks the derivatives of every registered term.
TERMS = {
    "electric": lambda H: Electric(permittivity=2.0, thickness=H),
    "pressure": lambda H: PressureWork(),
}
