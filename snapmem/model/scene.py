"""A scene: a reference meridian, the energy terms it needs, its boundary conditions and loads.

The total potential is Pi(q) = sum of the terms' energies. ``Scene.evaluate`` returns Pi, its
gradient and its Hessian (the tangent stiffness K) in band storage on the free degrees of
freedom. This one assembly is what Newton, continuation and time stepping all call.

Free degrees of freedom are numbered so that K is banded: ``Scene.dofs``, a
:class:`~snapmem.model.dofs.DofMap`, says how.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Iterable, Mapping

import numpy as np

from snapmem.kernels.banded import BandedMatrix
from snapmem.kernels.bordered import BodyMatrix
from snapmem.errors import SnapmemError, check_int, check_real
from snapmem.kernels.assembly import (edge_assembly, radius_max_step, residual_floor, scatter_add, state_check,
                                     volume_gradient)
from snapmem.kernels.switch import compiled
from snapmem.model.dofs import DofMap, node_areas
from snapmem.model.kinematics import EdgeKinematics, density_chain_rule
from snapmem.model.materials import Density
from snapmem.model.meridian import Meridian
from snapmem.model.terms import (DensityTerm, EdgeTerm, Electric, NodeTerm, PressureDeclaration, PressureWork,
                                 Stretching, Term)


@dataclass
class Evaluation:
    """Result of one assembly at a state q.

    Attributes
    ----------
    energy : float
        Total potential Pi [J].
    gradient : ndarray (2N,) or None
        dPi/dq over all degrees of freedom [N]; at fixed ones it is the reaction force (negated).
    residual : ndarray (n_free,) or None
        The gradient on the free degrees of freedom, in band order.
    stiffness : BandedMatrix, BodyMatrix or None
        K = d2Pi/dq2 on the free degrees of freedom, in band order [N/m] (bordered by one dense
        row and column per rigid body when the scene has bodies).
    residual_floor : float
        The residual's rounding floor [N] (snapmem.kernels.assembly.residual_floor): nodal forces
        are sums of edge forces computed from coordinate differences, so |R| cannot fall below
        about eps N max|edge force| (64 eps N times it is used), and a contact barrier's force
        carries its stiffness times the coordinates' round-off. Solvers converge at max(their
        tolerance, this floor).
    """

    energy: float
    gradient: np.ndarray | None
    residual: np.ndarray | None
    stiffness: BandedMatrix | None
    residual_floor: float = 0.0


class Scene:
    """A membrane problem: meridian, energy terms, fixed degrees of freedom and default loads.

    Parameters
    ----------
    meridian : Meridian
        Reference shape.
    thickness : float
        Reference thickness H [m].
    terms : iterable of Term
        Energy terms; include only the physics the scene needs.
    fixed : iterable of int
        Indices in q of degrees of freedom held at their reference value.
    loads : mapping, optional
        Default values of load parameters (``pressure`` [Pa], ``voltage`` [V]); every load
        a term depends on defaults to 0.
    name : str
        Name used in reports.
    parameters : mapping, optional
        The parameters the scene was built from (recorded beside results).
    start_guess : callable, optional
        loads -> q, a Newton starting state where the reference is singular (a flat plate).
    probes : mapping, optional
        Named scalar outputs of a state particular to this scene, q -> float (e.g. the
        balloon's equatorial ``stretch``); they join ``measures``.
    """

    def __init__(self, meridian: Meridian, thickness: float, terms: Iterable[Term],
                 fixed: Iterable[int] = (), loads: Mapping[str, float] | None = None,
                 name: str = "scene", parameters: Mapping | None = None,
                 start_guess: Callable[[dict], np.ndarray] | None = None,
                 probes: Mapping[str, Callable[[np.ndarray], float]] | None = None):
        self.meridian = meridian
        self.thickness = check_real("H", thickness, minimum=0.0, min_inclusive=False)
        self.terms = tuple(terms)
        self.density_terms = [t for t in self.terms if isinstance(t, DensityTerm)]
        self.edge_terms = [t for t in self.terms if isinstance(t, EdgeTerm)]
        self.node_terms = [t for t in self.terms if isinstance(t, NodeTerm)]
        unknown = [t for t in self.terms if not isinstance(t, (DensityTerm, EdgeTerm, NodeTerm))]
        if unknown:
            raise SnapmemError(f"terms: {unknown!r} are neither density, edge nor node terms")
        # rigid bodies of the node terms: one degree of freedom each, after the 2N node coordinates
        self.bodies = tuple(b for t in self.node_terms for b in t.bodies)
        self.n_node_dofs = 2 * meridian.nodes
        n_dof = self.n_node_dofs + len(self.bodies)
        if isinstance(fixed, (str, bytes)) or not isinstance(fixed, Iterable):
            raise SnapmemError(f"fixed = {fixed!r}: must be a list of degree-of-freedom numbers")
        self.fixed = tuple(sorted({check_int(f"fixed[{i}]", d, minimum=0) for i, d in enumerate(fixed)}))
        if any(d < 0 or d >= n_dof for d in self.fixed):
            raise SnapmemError(f"fixed = {list(self.fixed)}: degrees of freedom must lie in 0..{n_dof - 1}")
        self.name = name
        self.parameters = dict(parameters or {})
        self.start_guess = start_guess
        self.probes = dict(probes or {})
        names = {n for t in self.terms for n in t.loads}
        self.loads = {n: 0.0 for n in sorted(names)}
        for key, value in (loads or {}).items():
            self.loads[key] = check_real(key, value)
        self.weight = 2.0 * np.pi * meridian.mid_radius * meridian.length * self.thickness  # dV_bar (E,)
        #: the degree-of-freedom map (free dofs, band numbering, scatter maps, bodies)
        self.dofs = DofMap.build(meridian, self.fixed, [len(t.bodies) for t in self.node_terms])
        self.free, self.n_band, self.bandwidth = self.dofs.free, self.dofs.n_band, self.dofs.bandwidth
        self.edge_dofs = self.dofs.edge_dofs
        self.node_area = node_areas(meridian)
        self._domain_terms = [t for t in self.density_terms if t.restricts_domain]
        # the compiled membrane assembly takes the density terms and at most the pressure work
        self._compilable = len(self.edge_terms) <= 1 and all(
            isinstance(t.compiled(self), PressureDeclaration) for t in self.edge_terms)

    @property
    def n_free(self) -> int:
        return self.free.size

    def reference_state(self) -> np.ndarray:
        """q of the reference shape (and the bodies at their start heights), shape (2N + bodies,).

        A fresh copy each call (callers fill it in); the array itself is built once.
        """
        cached = self.__dict__.get("_reference")
        if cached is None:
            cached = self._reference = np.concatenate([self.meridian.q, [b.z0 for b in self.bodies]])
        return cached.copy()

    def node_coordinates(self, q: np.ndarray) -> np.ndarray:
        """Node positions (r_i, z_i) of a state, shape (N, 2) (a view of q)."""
        return q[: self.n_node_dofs].reshape(-1, 2)

    def body_coordinates(self, q: np.ndarray) -> list:
        """The heights of each node term's bodies, one array (k_t,) per node term."""
        return [q[s] for s in self.dofs.body_slices]

    def resolve_loads(self, loads: Mapping[str, float] | None) -> dict:
        """The scene's default loads updated by ``loads``; unknown names are an error."""
        out = dict(self.loads)
        if loads is not None and not isinstance(loads, Mapping):
            raise SnapmemError(f"loads = {loads!r}: must be a mapping of load names to values, "
                               f"e.g. {{'pressure': 0.01}}; this scene has {sorted(out) or 'none'}")
        for key, value in (loads or {}).items():
            if key not in out:
                raise SnapmemError(f"load {key!r}: this scene has no such load; it has {sorted(out) or 'none'}")
            out[key] = value if type(value) is float and math.isfinite(value) else check_real(key, value)
        return out

    # ----------------------------------------------------------------------------------------
    # assembly
    def kinematics(self, q: np.ndarray) -> EdgeKinematics:
        """Edge kinematics of q; the last state's are kept, since solvers ask for the same q several
        times in a row (assembly, domain check, measures, load derivative)."""
        nodes = q[: self.n_node_dofs]
        cached = self.__dict__.get("_kinematics_cache")
        if cached is not None and cached[0].shape == nodes.shape and np.array_equal(cached[0], nodes):
            return cached[1]
        kin = EdgeKinematics.of(self.meridian, nodes)
        self._kinematics_cache = (nodes.copy(), kin)
        return kin

    def density(self, kin: EdgeKinematics, loads) -> Density | None:
        """Sum of the density terms' densities, or None if the scene has none."""
        total = None
        for term in self.density_terms:
            d = term.density(kin, loads)
            total = d if total is None else total + d
        return total

    def evaluate(self, q: np.ndarray, loads: Mapping[str, float] | None = None, order: int = 2) -> Evaluation:
        """Total potential (order 0), its gradient (order >= 1) and stiffness (order 2) at q.

        Parameters
        ----------
        q : ndarray (2N,)
            State [m].
        loads : mapping, optional
            Load values overriding the scene's defaults.
        order : {0, 1, 2}
        """
        loads = self.resolve_loads(loads)
        kin = self.kinematics(q)
        dens = self.density(kin, loads)
        if order >= 1 and dens is not None and self._compilable and compiled():
            energy, gradient, band, force = self._membrane_compiled(q, kin, dens, loads, order)
        else:
            energy, gradient, band, force = self._membrane(q, kin, dens, loads, order)
        x = self.node_coordinates(q)
        barrier_rounding = 0.0
        for term, s in zip(self.node_terms, self.dofs.body_slices):
            local = term.node_local(x, q[s], self.node_area, loads, order)
            barrier_rounding = max(barrier_rounding, local.barrier_rounding)
            energy += local.energy
            if order >= 1:
                self._add_node_term(local, s, gradient, band, order)
            if order >= 2 and self.bodies:
                self._add_border(local, s, band)
        if order < 1:
            return Evaluation(energy, None, None, None)
        stiffness = None
        if order >= 2:
            stiffness = BandedMatrix.from_lower(band[: self.dofs.band_size].reshape(self.n_band, self.bandwidth + 1).T,
                                                self.bandwidth)
            if self.bodies:
                stiffness = BodyMatrix(stiffness, band.border.T, band.corner)
        floor = residual_floor(self.meridian.nodes, force, barrier_rounding)
        return Evaluation(energy, gradient, gradient[self.free], stiffness, floor)

    def _membrane(self, q, kin, dens, loads, order):
        """Energy, gradient (n_dof,), flat band (with a trash slot; None below order 2) and the
        largest edge force entry [N] of the density and edge terms (for the rounding floor), by numpy."""
        energy = 0.0
        grad_local = hess_local = None
        if dens is not None:
            energy += float(self.weight @ dens.w)
            if order >= 1:
                grad_local, hess_local = density_chain_rule(kin, dens, self.weight, order)
        for term in self.edge_terms:
            e, g, h = term.edge_local(kin, loads, order)
            energy += e
            if order >= 1:
                grad_local = g if grad_local is None else _accumulate(grad_local, g)
            if order >= 2:
                hess_local = h if hess_local is None else _accumulate(hess_local, h)
        if order < 1:
            return energy, None, None, 0.0
        if grad_local is None:                                  # node terms only
            return energy, np.zeros(q.size), self._empty_band(order), 0.0
        gradient = np.bincount(self.edge_dofs.ravel(), grad_local.ravel(), minlength=q.size)
        band = None
        if order >= 2:
            band = _Band(np.bincount(self.dofs.hess_index, hess_local.reshape(-1), minlength=self.dofs.band_size + 1))
        return energy, gradient, band, float(np.max(np.abs(grad_local)))

    def _membrane_compiled(self, q, kin, dens, loads, order):
        """As :meth:`_membrane`, by the compiled kernel (snapmem.kernels.assembly.edge_assembly)."""
        pressure = loads["pressure"] if self.edge_terms else 0.0
        m = self.meridian
        gradient, band, volume, force = edge_assembly(
            q, m.edges, kin.inv_length, kin.inv_mid_radius, self.weight, dens.w1, dens.w2, dens.w11, dens.w12,
            dens.w22, pressure, self.dofs.hess_index, self.dofs.band_size, order)
        energy = float(self.weight @ dens.w) - pressure * volume
        return energy, gradient, (_Band(band) if order >= 2 else None), force

    def _empty_band(self, order):
        return _Band(np.zeros(self.dofs.band_size + 1)) if order >= 2 else None

    def _add_node_term(self, local, s, gradient, band, order) -> None:
        """Add a node term's gradient and Hessian (node blocks, edge blocks, body parts) in place."""
        nodes = slice(None) if local.nodes is None else local.nodes
        edges = slice(None) if local.edges is None else local.edges
        if local.gradient is not None:
            gradient[: self.n_node_dofs].reshape(-1, 2)[nodes] += local.gradient[:, :2]     # nodes are distinct
            gradient[s] += local.gradient[:, 2:].sum(axis=0)
        if local.body_gradient is not None:
            gradient[s] += local.body_gradient
        if local.edge_gradient is not None:                  # edges share nodes: accumulate
            eg = local.edge_gradient
            scatter_add(gradient, self.edge_dofs[edges].ravel(), eg[:, :4].ravel())
            gradient[s] += eg[:, 4:].sum(axis=0)
        if order < 2:
            return
        if local.hessian is not None:
            scatter_add(band.values, self.dofs.node_hess[nodes].ravel(), local.hessian[:, :2, :2].ravel())
        if local.edge_hessian is not None:
            he = local.edge_hessian[:4, :4]
            scatter_add(band.values, self.dofs.hess_index.reshape(16, -1)[:, edges].ravel(), he.reshape(16, -1).ravel())

    def _add_border(self, local, s, band) -> None:
        """Add a node term's node-body and body-body blocks to the border and corner of ``band``."""
        k = len(self.bodies)
        if band.border is None:
            band.border, band.corner = np.zeros((k, self.n_band)), np.zeros((k, k))
        cols = range(s.start - self.n_node_dofs, s.stop - self.n_node_dofs)
        if not cols:
            return
        border, corner = band.border, band.corner                   # border stored transposed: (k, n_band)
        block = (slice(cols.start, cols.stop),) * 2
        if local.hessian is not None:
            nodes = slice(None) if local.nodes is None else local.nodes
            pos = self.dofs.node_pos[nodes].ravel()
            h = local.hessian
            for a, col in enumerate(cols):
                scatter_add(border[col], pos, h[:, :2, 2 + a].ravel())
            corner[block] += h[:, 2:, 2:].sum(axis=0)
        if local.body_hessian is not None:
            corner[block] += local.body_hessian
        if local.edge_hessian is not None:
            edges = slice(None) if local.edges is None else local.edges
            he = local.edge_hessian                                # (4 + k, 4 + k, M)
            epos = self.dofs.edge_pos[edges].T.ravel()             # entry-major (4, M)
            for a, col in enumerate(cols):
                scatter_add(border[col], epos, he[:4, 4 + a].ravel())
            corner[block] += he[4:, 4:].sum(axis=-1)

    def energy(self, q, loads=None) -> float:
        return self.evaluate(q, loads, order=0).energy

    def gradient(self, q, loads=None) -> np.ndarray:
        """dPi/dq over all degrees of freedom, shape (2N,) [N]."""
        return self.evaluate(q, loads, order=1).gradient

    def load_derivative(self, q: np.ndarray, name: str, loads: Mapping[str, float] | None = None) -> np.ndarray:
        """d(residual)/d(load ``name``) on the free degrees of freedom, shape (n_free,)."""
        loads = self.resolve_loads(loads)
        if name not in loads:
            raise SnapmemError(f"load {name!r}: this scene has no such load; it has {sorted(loads) or 'none'}")
        out = np.zeros(q.size)
        kin = None
        for term in self.density_terms + self.edge_terms:
            if name not in term.loads:
                continue
            if type(term) is PressureWork and compiled():      # -dV/dq, compiled
                out -= volume_gradient(q, self.meridian.edges, q.size)
                continue
            kin = self.kinematics(q) if kin is None else kin
            if isinstance(term, DensityTerm):
                local = density_chain_rule(kin, term.load_density(kin, loads, name), self.weight, 1)[0]
            else:
                local = term.load_gradient(kin, loads, name)
            out += np.bincount(self.edge_dofs.ravel(), local.ravel(), minlength=q.size)
        return out[self.free]                                  # node terms carry no load

    # ----------------------------------------------------------------------------------------
    # the domain every state must stay in
    def inadmissible(self, q: np.ndarray) -> str | None:
        """Why q is outside the model's domain (negative radius, zero length, material lock), or None."""
        bad = state_check(q, self.dofs.radius_dofs)
        if bad == -2:
            return "state has NaN or inf"
        if bad >= 0:
            return f"radius of node {bad // 2} is not positive"
        kin = self.kinematics(q)
        if kin.l.min() <= 0:
            return "an edge has collapsed to zero length"
        for term in self._domain_terms:
            ok = term.admissible(kin)
            if not np.all(ok):
                return f"edge {int(np.flatnonzero(~ok)[0])} is outside the domain of {term!r}"
        x = self.node_coordinates(q)
        for term, s in zip(self.node_terms, self.dofs.body_slices):
            why = term.admissible(x, q[s])
            if why is not None:
                return why
        return None

    def max_step(self, q: np.ndarray, dq: np.ndarray) -> float:
        """Largest step fraction alpha <= 1 keeping free radii positive (fraction to boundary 0.9)
        and every term's state admissible (no node crossing a contact gap of zero)."""
        alpha = radius_max_step(q, dq, self.n_node_dofs, 0.9)
        if not self.node_terms:
            return alpha
        x, dx = self.node_coordinates(q), self.node_coordinates(dq)
        for term, s in zip(self.node_terms, self.dofs.body_slices):
            alpha = min(alpha, term.max_step(x, q[s], dx, dq[s]))
        return alpha

    # ----------------------------------------------------------------------------------------
    # outputs
    @property
    def mu(self) -> float:
        """Shear modulus [Pa] of the stretching law (normalises pressure and voltage)."""
        for term in self.density_terms:
            if isinstance(term, Stretching):
                return float(term.law.mu)
        raise SnapmemError(f"scene {self.name!r} has no stretching term, so no shear modulus")

    @property
    def permittivity(self) -> float | None:
        for term in self.density_terms:
            if isinstance(term, Electric):
                return term.permittivity
        return self.parameters.get("eps")

    def e_hat(self, voltage: float) -> float:
        """Normalised electric load E_hat = (phi/H) sqrt(eps/mu) of a voltage phi [V]."""
        eps = self.permittivity
        return 0.0 if eps is None else voltage / self.thickness * np.sqrt(eps / self.mu)

    def volume(self, q: np.ndarray) -> float:
        """Volume enclosed by the revolved meridian [m^3] (above z = 0 for an open one ending there)."""
        return float(PressureWork.volume_local(self.kinematics(q), 0)[0].sum())

    def displacement(self, q: np.ndarray) -> np.ndarray:
        """Node displacement magnitudes |x - x_bar|, shape (N,) [m]."""
        d = q[: self.n_node_dofs] - self.meridian.q
        return np.hypot(d[0::2], d[1::2])

    def stretches(self, q: np.ndarray):
        """(lam1, lam2) of every edge, each of shape (E,)."""
        kin = self.kinematics(q)
        return kin.lam1, kin.lam2

    def tensions(self, q: np.ndarray, loads=None):
        """Principal membrane tensions (T1 meridional, T2 hoop) of every edge [N/m], each (E,).

        T1 = (H/lam2) dW/dlam1, T2 = (H/lam1) dW/dlam2 with W the sum of all densities
        (electric term included). Non-positive tension means wrinkling or slack.
        """
        kin = self.kinematics(q)
        dens = self.density(kin, self.resolve_loads(loads))
        return self.thickness / kin.lam2 * dens.w1, self.thickness / kin.lam1 * dens.w2

    def measures(self, q: np.ndarray, loads=None) -> dict:
        """Scalar outputs of a state: volume, u_max, stretch_max, min_tension, taut."""
        lam1, lam2 = self.stretches(q)
        t1, t2 = self.tensions(q, loads)
        min_tension = float(min(t1.min(), t2.min()))
        out = {"volume": self.volume(q), "u_max": float(self.displacement(q).max()),
               "stretch_max": float(max(lam1.max(), lam2.max())),
               "min_tension": min_tension, "taut": bool(min_tension > 0)}
        out.update({name: float(probe(q)) for name, probe in self.probes.items()})
        return out

    @property
    def force_scale(self) -> float:
        """Characteristic force mu H L [N], used for residual tolerances."""
        return self.mu * self.thickness * self.meridian.size

    def __repr__(self):
        return (f"Scene({self.name!r}, nodes={self.meridian.nodes}, terms={[type(t).__name__ for t in self.terms]}, "
                f"fixed={list(self.fixed)}, loads={self.loads})")


class _Band:
    """The stiffness being assembled: flat band values (ab.T in C order, one trailing trash slot
    for fixed degrees of freedom) and, with rigid bodies, the border and corner blocks."""

    __slots__ = ("values", "border", "corner")

    def __init__(self, values: np.ndarray):
        self.values, self.border, self.corner = values, None, None

    def __getitem__(self, key):
        return self.values[key]


def _accumulate(total: np.ndarray, part: np.ndarray) -> np.ndarray:
    """total + part, in place (no new E-sized temporary)."""
    total += part
    return total
