"""Contact with rigid bodies: the IPC log barrier on the gap between each node and a body.

For a gap d > 0 between node i and a body, with barrier width d_hat [m],

    b(d) = -(d - d_hat)^2 ln(d / d_hat)   for d < d_hat,   0 for d >= d_hat,

and the node's energy is kappa A_i b(d_i) / d_hat with A_i its reference ring area
2 pi r_bar_i l_bar_i (a pole node: its cap). b / d_hat is a length, so kappa is a contact
pressure [Pa]: the barrier pushes with kappa |b'(d)| per unit area, 1.19 kappa at d = d_hat / 2,
growing without bound as d -> 0. The energy is C2 at d = d_hat (b = b' = 0 there) and infinite
at d = 0, and ``max_step`` keeps every Newton step short of d = 0 (fraction to the boundary 0.9),
so no accepted state ever penetrates a body.

Bodies: a rod inside a torus (d = r - Rw), a cylindrical shell around it (d = Rw - r), a plane
(d = +-(z - z0)) and a ball on the axis (d = |x - (0, zb)| - rb) whose height zb is either fixed
or a degree of freedom of its own (a :class:`~snapmem.model.terms.RigidBody` with mass and weight).
The chain rule from gap to node coordinates is written once, in :class:`Contact`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from snapmem.kernels.contact import (ball_edge_barrier, ball_edge_gaps, ball_min_gap, ball_node_max_step, ipc_barrier,
                                    linear_barrier, linear_max_step, linear_min_gap)
from snapmem.errors import check_real
from snapmem.model.terms import BallDeclaration, LinearContactDeclaration, NodeLocal, NodeTerm, RigidBody

FRACTION_TO_BOUNDARY = 0.9


def barrier_rounding(hessian: np.ndarray, coordinates: np.ndarray, extra: float = 0.0) -> float:
    """A barrier's largest |Hessian entry| [N/m] times the largest of |coordinates| and |extra| [m]
    (the coordinates its active gaps are computed from, and the body's offset or centre): eps times
    it is the noise their round-off puts in its forces [N], a part of the residual's rounding floor
    (snapmem.kernels.assembly.residual_floor; the compiled step's assembly takes the same). 0 if
    no gap is active."""
    if not hessian.size:
        return 0.0
    return float(np.max(np.abs(hessian))) * max(float(np.max(np.abs(coordinates))), abs(extra))


def barrier(d: np.ndarray, dhat: float, order: int = 2):
    """IPC barrier b(d) and its first two derivatives in d (zero where d >= dhat; +inf for d <= 0).

    Returns (b, b', b'') with entries None above ``order``; each of the shape of ``d`` [m^2, m, 1].
    The formula is :func:`snapmem.kernels.contact.ipc_barrier`'s (the compiled kernels' own).
    """
    d = np.asarray(d, dtype=float)
    if d.size and 0.0 < d.min() and d.max() < dhat:     # all active and admissible: the formulas alone
        b, b1, b2 = ipc_barrier.py_func(d, dhat, 1.0)
    else:
        dd = np.where(d < dhat, d, dhat)                 # inactive: b = b' = b'' = 0 at d = dhat
        with np.errstate(divide="ignore", invalid="ignore"):
            b, b1, b2 = ipc_barrier.py_func(dd, dhat, 1.0)
        b = np.where(d > 0, b, np.inf)
    return b, (b1 if order >= 1 else None), (b2 if order >= 2 else None)


@dataclass(frozen=True, kw_only=True)
class Contact(NodeTerm):
    """Base of the contact barriers: a gap per node and the barrier chain rule.

    Attributes
    ----------
    kappa : float
        Contact pressure scale [Pa] (> 0).
    dhat : float
        Barrier width [m] (> 0): nodes farther than this feel nothing.
    nodes : tuple of int, optional
        The nodes that can touch this body (default all); leave out a node held fixed on it.
    """

    kappa: float
    dhat: float
    nodes: tuple | None = None

    def __post_init__(self):
        check_real("kappa", self.kappa, minimum=0.0, min_inclusive=False)
        check_real("dhat", self.dhat, minimum=0.0, min_inclusive=False)
        object.__setattr__(self, "_index", None if self.nodes is None else np.asarray(self.nodes, dtype=int))
        object.__setattr__(self, "_all", None)         # arange(N), made on first use

    # a subclass gives the gap of nodes x (M, 2) from the body at heights y (k,):
    # d (M,), its gradient (M, 2 + k) and Hessian (M, 2 + k, 2 + k) (None for a linear gap)
    def gap(self, x: np.ndarray, y: np.ndarray, order: int):
        raise NotImplementedError

    def _selected(self, x):
        return x if self._index is None else x[self._index]

    #: (axis, sign, offset) of a gap linear in one coordinate, d = sign * x[:, axis] + offset
    #: (rod, shell, plane): their barrier, step limit and gaps go through compiled loops
    linear = None

    def _node_index(self, n: int) -> np.ndarray:
        if self._index is not None:
            return self._index
        if self._all is None or self._all.size != n:
            object.__setattr__(self, "_all", np.arange(n))
        return self._all

    def gaps(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Gap of every node of the term (in ``nodes`` order), shape (M,) [m]."""
        return self.gap(self._selected(x), y, 0)[0]

    def node_local(self, x, y, area, loads, order):
        idx = self._node_index(x.shape[0])
        if self.linear is not None:                # rod, shell, plane: no bodies, one compiled pass
            axis, sign, offset = self.linear
            energy, near, grad, hess = linear_barrier(x, idx, axis, sign, offset, self._coef(area), self.dhat, order)
            out = NodeLocal(energy, nodes=near)
            if order >= 1:
                out.gradient = grad
            if order >= 2:
                out.hessian = hess
                out.barrier_rounding = barrier_rounding(hess, x[near, axis], offset)
            return out
        d = self.gap(x[idx], y, 0)[0]
        near = d < self.dhat                       # only nodes within the barrier width feel it
        idx = idx[near]
        out = NodeLocal(self.body_energy(y), nodes=idx)
        out.body_gradient, out.body_hessian = self.body_energy_derivatives(y, order)
        if idx.size == 0:                          # nothing near: no node parts at all
            return out
        d, dg, dh = self.gap(x[idx], y, order)
        c = self.kappa * area[idx] / self.dhat
        b, b1, b2 = barrier(d, self.dhat, order)
        out.energy += float(c @ b)
        if order < 1:
            return out
        out.gradient = (c * b1)[:, None] * dg
        if order >= 2:
            out.hessian = (c * b2)[:, None, None] * dg[:, :, None] * dg[:, None, :]
            if dh is not None:
                out.hessian += (c * b1)[:, None, None] * dh
            out.barrier_rounding = barrier_rounding(out.hessian, x[idx], self._centre(y))
        return out

    def body_energy(self, y) -> float:
        """Energy of the body alone (its weight) [J]."""
        return 0.0

    def _centre(self, y) -> float:
        """The body coordinate a node gap is measured from [m] (a ball's centre height; 0 here)."""
        return 0.0

    def body_energy_derivatives(self, y, order):
        return None, None

    def admissible(self, x, y):
        if self.linear is not None and linear_min_gap(x, self._node_index(x.shape[0]), *self.linear) > 0:
            return None
        d = self.gaps(x, y)
        if np.any(d <= 0):
            i = int(np.argmin(d))
            node = i if self.nodes is None else self.nodes[i]
            return f"node {node} touches or penetrates {type(self).__name__} (gap {d[i]:.3g} m)"
        return None

    def _coef(self, area):
        """kappa A_i / dhat of every node (kept for the scene's areas)."""
        cached = self.__dict__.get("_coef_cache")
        if cached is None or cached[0] is not area:
            cached = (area, self.kappa * area / self.dhat)
            object.__setattr__(self, "_coef_cache", cached)
        return cached[1]

    def max_step(self, x, y, dx, dy):
        """Largest alpha <= 1 keeping every gap above (1 - 0.9) of the way to zero (linear gaps)."""
        if self.linear is not None:
            axis, sign, offset = self.linear
            return float(linear_max_step(x, dx, self._node_index(x.shape[0]), axis, sign, offset,
                                         FRACTION_TO_BOUNDARY))
        xs, dxs = self._selected(x), self._selected(dx)
        d = self.gap(xs, y, 0)[0]
        dd = self.gap_rate(xs, y, dxs, dy)
        closing = dd < 0
        if not np.any(closing):
            return 1.0
        return float(min(1.0, FRACTION_TO_BOUNDARY * np.min(d[closing] / -dd[closing])))

    def gap_rate(self, x, y, dx, dy):
        """d(gap)/d(alpha) along the step for a gap linear in the coordinates."""
        _, g, _ = self.gap(x, y, 1)
        return g[:, 0] * dx[:, 0] + g[:, 1] * dx[:, 1] + (g[:, 2:] @ dy if g.shape[1] > 2 else 0.0)

    def compiled(self, scene, bodies=slice(0, 0)):
        """A linear gap without bodies (rod, shell, plane) declares its nodes, gap and weights."""
        if self.linear is None or self.bodies:
            return None
        axis, sign, offset = self.linear
        return LinearContactDeclaration(np.asarray(self._node_index(scene.meridian.nodes), dtype=np.int64), int(axis),
                                        float(sign), float(offset), float(self.dhat), self._coef(scene.node_area))

    def forces(self, x: np.ndarray, y: np.ndarray, area: np.ndarray) -> np.ndarray:
        """Normal force of the body on each node's ring, |kappa A_i b'(d_i) / d_hat|, shape (M,) [N]."""
        idx = np.arange(x.shape[0]) if self._index is None else self._index
        d = self.gap(x[idx], y, 0)[0]
        return np.abs(self.kappa * area[idx] / self.dhat * barrier(d, self.dhat, 1)[1])


def _linear_gap(d, grad_row, order):
    m = d.size
    return d, (np.broadcast_to(grad_row, (m, len(grad_row))) if order >= 1 else None), None


@dataclass(frozen=True, kw_only=True)
class Rod(Contact):
    """A rigid rod of radius ``radius`` [m] on the axis, inside the membrane: d = r - radius."""

    radius: float

    @property
    def linear(self):
        return 0, 1.0, -self.radius

    def gap(self, x, y, order):
        return _linear_gap(x[:, 0] - self.radius, np.array([1.0, 0.0]), order)


@dataclass(frozen=True, kw_only=True)
class Shell(Contact):
    """A rigid cylindrical shell of inner radius ``radius`` [m] around the membrane: d = radius - r."""

    radius: float

    @property
    def linear(self):
        return 0, -1.0, self.radius

    def gap(self, x, y, order):
        return _linear_gap(self.radius - x[:, 0], np.array([-1.0, 0.0]), order)


@dataclass(frozen=True, kw_only=True)
class Plane(Contact):
    """A rigid plane z = ``z0`` [m]; the membrane stays above it (``below=False``) or below it."""

    z0: float
    below: bool = False

    @property
    def linear(self):
        s = -1.0 if self.below else 1.0
        return 1, s, -s * self.z0

    def gap(self, x, y, order):
        s = -1.0 if self.below else 1.0
        return _linear_gap(s * (x[:, 1] - self.z0), np.array([0.0, s]), order)


@dataclass(frozen=True, kw_only=True, eq=False)
class Ball(Contact):
    """A rigid ball of radius ``radius`` [m] centred on the axis: d = |x - (0, zb)| - radius.

    With ``mass`` None the ball is held at height ``z0``; with a mass [kg] its height zb is a
    degree of freedom of its own (a :class:`RigidBody` named ``name``, starting at ``z0``) with
    weight -mass * gravity * zb (``gravity`` [m/s^2] is signed along z, e.g. -10).

    With ``meridian`` given, the gap is each *edge's* distance to the ball (point-segment, IPC's
    point-edge distance: to the nearer end node, or to the edge's line where the centre projects
    inside it) and each edge's barrier is weighted by its reference ring area 2 pi r_m_bar l_bar.
    Then a long, stretched edge cannot pass through the ball between its two nodes, which node
    gaps alone allow (a snap stretches the balloon's cap edges ~20x). ``nodes`` is ignored then.
    """

    radius: float
    z0: float
    mass: float | None = None
    gravity: float = 0.0
    name: str = "ball"
    meridian: object = None

    def __post_init__(self):
        super().__post_init__()
        check_real("radius", self.radius, minimum=0.0, min_inclusive=False)
        if self.mass is not None:
            check_real("mass", self.mass, minimum=0.0, min_inclusive=False)
            object.__setattr__(self, "bodies", (RigidBody(self.name, self.z0, self.mass),))
        if self.meridian is not None:
            m = self.meridian
            object.__setattr__(self, "_edge_area", 2.0 * np.pi * m.mid_radius * m.length)
            object.__setattr__(self, "_edge_coef", self.kappa * self._edge_area / self.dhat)

    # ---- edges: point-segment distance of the centre c = (0, zb) to each edge [a, b]
    def edge_gap(self, x, y, order, which=None):
        """Distance minus radius of each edge (or edges ``which``), with derivatives in
        (r_a, z_a, r_b, z_b[, zb]): d (M,), gradient (M, 4 + k), Hessian (M, 4 + k, 4 + k)."""
        edges = self.meridian.edges if which is None else self.meridian.edges[which]
        a, b = x[edges[:, 0]], x[edges[:, 1]]
        zc = self._centre(y)
        u = b - a
        w = np.stack([-a[:, 0], zc - a[:, 1]], axis=1)                # c - a
        L2 = np.einsum("ij,ij->i", u, u)
        t = np.einsum("ij,ij->i", w, u) / L2
        if order == 0:                               # distances only: the closest point of each segment
            tc = np.clip(t, 0.0, 1.0)
            return np.hypot(a[:, 0] + tc * u[:, 0], a[:, 1] + tc * u[:, 1] - zc) - self.radius, None, None
        end_a, end_b = t <= 0, t >= 1
        inner = ~(end_a | end_b)
        n = 5 if self.bodies else 4
        m = a.shape[0]
        d = np.empty(m)
        g = np.zeros((m, n)) if order >= 1 else None
        h = np.zeros((m, n, n)) if order >= 2 else None
        for mask, cols, pts in ((end_a, [0, 1], a), (end_b, [2, 3], b)):
            if np.any(mask):
                dn, gn, hn = self.gap(pts[mask], y, order)         # node distance, (r, z[, zb])
                d[mask] = dn
                idx = cols + ([4] if self.bodies else [])
                if order >= 1:
                    g[np.ix_(np.flatnonzero(mask), idx)] = gn
                if order >= 2:
                    rows = np.flatnonzero(mask)
                    h[rows[:, None, None], np.array(idx)[None, :, None], np.array(idx)[None, None, :]] = hn
        if np.any(inner):
            ui, wi = u[inner], w[inner]
            C = ui[:, 0] * wi[:, 1] - ui[:, 1] * wi[:, 0]
            L = np.sqrt(L2[inner])
            sgn = np.sign(C)
            d[inner] = sgn * C / L - self.radius
            if order >= 1:
                Ju = _JU[:, :n]
                gC = np.stack([ui[:, 1] - wi[:, 1], wi[:, 0] - ui[:, 0], wi[:, 1], -wi[:, 0]]
                              + ([ui[:, 0]] if self.bodies else []), axis=1)
                uh = ui / L[:, None]
                gL = uh @ Ju                                              # (M, n)
                g[inner] = sgn[:, None] * (gC / L[:, None] - (C / L ** 2)[:, None] * gL)
                if order >= 2:
                    HC = _HC[:n, :n]
                    P = (np.eye(2)[None] - uh[:, :, None] * uh[:, None, :]) / L[:, None, None]
                    HL = np.einsum("ki,mkl,lj->mij", Ju, P, Ju)
                    outer = gC[:, :, None] * gL[:, None, :]
                    hi = (HC[None] / L[:, None, None] - (outer + outer.transpose(0, 2, 1)) / (L ** 2)[:, None, None]
                          - (C / L ** 2)[:, None, None] * HL
                          + (2 * C / L ** 3)[:, None, None] * gL[:, :, None] * gL[:, None, :])
                    h[inner] = sgn[:, None, None] * hi
        return d, g, h

    def _centre(self, y):
        return float(y[0]) if self.bodies else self.z0

    def gap(self, x, y, order):
        pr, pz = x[:, 0], x[:, 1] - self._centre(y)
        s = np.hypot(pr, pz)
        d = s - self.radius
        if order < 1:
            return d, None, None
        nr, nz = pr / s, pz / s
        cols = [nr, nz, -nz] if self.bodies else [nr, nz]
        g = np.stack(cols, axis=1)
        if order < 2:
            return d, g, None
        hrr, hrz, hzz = nz * nz / s, -nr * nz / s, nr * nr / s     # (I - n n^T) / s
        if self.bodies:
            h = np.stack([np.stack([hrr, hrz, -hrz], -1), np.stack([hrz, hzz, -hzz], -1),
                          np.stack([-hrz, -hzz, hzz], -1)], -2)
        else:
            h = np.stack([np.stack([hrr, hrz], -1), np.stack([hrz, hzz], -1)], -2)
        return d, g, h

    def max_step(self, x, y, dx, dy):
        """Largest alpha <= 1 before any node reaches the sphere (first root of |p + a dp| = rb), times 0.9;
        with edges, further halved until every edge keeps 10% of its gap."""
        alpha = self._node_max_step(x if self.meridian is None else x, y, dx, dy)
        if self.meridian is not None:
            alpha = self._edges_clear(x, y, dx, np.asarray(dy, dtype=float), alpha)
        return alpha

    def _node_max_step(self, x, y, dx, dy):
        xs, dxs = self._selected(x), self._selected(dx)
        dzb = float(dy[0]) if self.bodies else 0.0
        return float(ball_node_max_step(xs, dxs, self._centre(y), dzb, self.radius, FRACTION_TO_BOUNDARY))

    def _edges_clear(self, x, y, dx, dy, alpha):
        """Largest alpha' <= alpha (halving) at which no edge reaches the ball, keeping 10% of each gap."""
        zc, dzc = self._centre(y), (float(dy[0]) if self.bodies else 0.0)
        edges = self.meridian.edges
        floor = (1.0 - FRACTION_TO_BOUNDARY) * min(float(ball_min_gap(x, dx, 0.0, edges, zc, dzc, self.radius)),
                                                     self.dhat)
        for _ in range(40):
            if ball_min_gap(x, dx, alpha, edges, zc, dzc, self.radius) > floor:
                return alpha
            alpha *= 0.5
        return alpha

    def node_local(self, x, y, area, loads, order):
        if self.meridian is None:
            return super().node_local(x, y, area, loads, order)
        energy, which, grad, hess = ball_edge_barrier(x, self.meridian.edges, self._centre(y), self.radius,
                                                      self.dhat, self._edge_coef, bool(self.bodies), order)
        out = NodeLocal(energy + self.body_energy(y), edges=which)
        out.body_gradient, out.body_hessian = self.body_energy_derivatives(y, order)
        if order >= 1:
            out.edge_gradient = grad
        if order >= 2:
            out.edge_hessian = hess
            out.barrier_rounding = barrier_rounding(hess, x[self.meridian.edges[which]], self._centre(y))
        return out

    def gaps(self, x, y):
        if self.meridian is None:
            return super().gaps(x, y)
        return ball_edge_gaps(x, self.meridian.edges, self._centre(y), self.radius)

    def admissible(self, x, y):
        if self.meridian is None:
            return super().admissible(x, y)
        d = self.gaps(x, y)
        if np.any(d <= 0):
            i = int(np.argmin(d))
            return f"edge {i} touches or crosses the ball (gap {d[i]:.3g} m)"
        return None

    def forces(self, x, y, area):
        if self.meridian is None:
            return super().forces(x, y, area)
        d = self.gaps(x, y)
        return np.abs(self._edge_coef * barrier(d, self.dhat, 1)[1])

    def compiled(self, scene, bodies=slice(0, 0)):
        """A ball touching edges (``meridian`` given, no ``nodes``), held or with its one body."""
        if self.meridian is None or self.nodes is not None or len(self.bodies) > 1:
            return None
        return BallDeclaration(float(self.radius), float(self.dhat), np.asarray(self._edge_coef, dtype=float),
                               float(self.z0), bodies.start if self.bodies else -1,
                               -self.mass * self.gravity if self.bodies else 0.0)

    def body_energy(self, y):
        return -self.mass * self.gravity * float(y[0]) if self.bodies else 0.0

    def body_energy_derivatives(self, y, order):
        if not self.bodies:
            return None, None
        return np.array([-self.mass * self.gravity]), np.zeros((1, 1))


# constant Jacobians of the point-line distance: u = b - a and w = c - a in (r_a, z_a, r_b, z_b, zc)
_JU = np.array([[-1.0, 0.0, 1.0, 0.0, 0.0], [0.0, -1.0, 0.0, 1.0, 0.0]])
_JW = np.array([[-1.0, 0.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0, 1.0]])
_M = np.array([[0.0, 1.0], [-1.0, 0.0]])                  # C = u^T M w = u_r w_z - u_z w_r
_HC = _JU.T @ _M @ _JW + _JW.T @ _M.T @ _JU


def contact_terms(scene) -> list:
    """The contact terms of a scene, in order."""
    return [t for t in scene.node_terms if isinstance(t, Contact)]


def contact_names(scene) -> list:
    """Output name of every contact term of the scene, in order: the body's class name in lower
    case (``rod``, ``shell``, ``plane``, ``ball``), numbered if a scene has two of a kind."""
    names, seen = [], {}
    for term in contact_terms(scene):
        name = type(term).__name__.lower()
        seen[name] = seen.get(name, 0) + 1
        names.append(name if seen[name] == 1 else f"{name}{seen[name]}")
    return names


def contact_report(scene, q: np.ndarray) -> dict:
    """Total normal force [N] and smallest gap [m] of every contact term of the scene at q.

    Keys are ``<name>_force`` and ``<name>_gap`` (names: :func:`contact_names`).
    """
    x = scene.node_coordinates(q)
    out = {}
    terms = [(t, y) for t, y in zip(scene.node_terms, scene.body_coordinates(q)) if isinstance(t, Contact)]
    for name, (term, y) in zip(contact_names(scene), terms):
        out[f"{name}_force"] = float(term.forces(x, y, scene.node_area).sum())
        out[f"{name}_gap"] = float(term.gaps(x, y).min())
    return out


#: Contact examples for the derivative tests, by name: dhat -> term (active on every test shape,
#: whose nodes lie within about 13 of the origin).
CONTACT_EXAMPLES = {
    "contact_rod": lambda dhat: Rod(kappa=3.0, dhat=dhat, radius=0.1, nodes=tuple(range(1, 9))),
    "contact_shell": lambda dhat: Shell(kappa=3.0, dhat=dhat, radius=40.0),
    "contact_plane": lambda dhat: Plane(kappa=3.0, dhat=dhat, z0=-20.0),
    "contact_ball": lambda dhat: Ball(kappa=3.0, dhat=dhat, radius=0.5, z0=30.0),
    "contact_ball_body": lambda dhat: Ball(kappa=3.0, dhat=dhat, radius=0.5, z0=30.0, mass=2.0, gravity=-10.0),
}



def _register():
    from snapmem.model.terms import TERMS
    for name in ("contact_rod", "contact_shell", "contact_plane", "contact_ball"):
        TERMS[name] = (lambda example: lambda H: example(30.0))(CONTACT_EXAMPLES[name])


_register()
