"""What is continued: the unknowns, the parameter and the equations of a branch.

:class:`LoadProblem` continues R(q; loads) = 0 in one load; :class:`VolumeProblem` continues
R = 0 with the volume V(q) = V0 as the parameter (the pressure becomes an unknown). Everything
that differs between them (the start, the stiffness within the Jacobian, the borders a null
mode may couple to, how a critical point is classified) is a method here, so the tracer treats
both alike.
"""

from __future__ import annotations

import math

import numpy as np

from snapmem.continuation.options import CONTROLS
from snapmem.errors import SnapmemError
from snapmem.kernels.banded import BorderedMatrix, eigenvalues_near_zero
from snapmem.model.constraints import multiplier_count
from snapmem.model.local_checks import failure_margins
from snapmem.model.scene import Scene


class LoadProblem:
    """Equilibria R(q; loads) = 0 with one load as the parameter: x = free dofs.

    Attributes
    ----------
    jacobian_is_stiffness : bool
        The Jacobian of the continued equations is the stiffness K itself. Then K is singular
        exactly where the parameter turns back (a limit point is the zero of the tangent's
        parameter component), and a critical point can be polished by Newton on [R = 0, g = 0].
    """

    jacobian_is_stiffness = True

    def __init__(self, scene: Scene, control: str):
        self.scene, self.control = scene, control
        self.base = scene.resolve_loads(None)
        load = "voltage" if control == "E_hat" else control
        if load not in self.base:
            raise SnapmemError(f"control = {control!r}: scene {scene.name!r} has no {load} load "
                               f"(it has {sorted(self.base) or 'none'}); "
                               + ("build it with with_loads=('voltage',)" if load == "voltage" else ""))
        self.load = load
        # d load / d lambda
        self.factor = 1.0 if control != "E_hat" else scene.thickness * math.sqrt(scene.mu / scene.permittivity)
        L = scene.meridian.size
        self.x_weight = np.full(scene.n_free, 1.0 / (L * L * scene.meridian.nodes))
        #: Lagrange multipliers of linear constraints among the unknowns (a free balloon's support):
        #: each adds one negative eigenvalue to the saddle stiffness, not counted in the stability
        self.multipliers = multiplier_count(scene)
        self.lam_scale = {"pressure": scene.mu * scene.thickness / L,
                          "voltage": scene.thickness * math.sqrt(scene.mu / (scene.permittivity or 1.0)),
                          "E_hat": 1.0}[control]

    @property
    def n(self) -> int:
        return self.scene.n_free

    def loads(self, lam: float) -> dict:
        return {**self.base, self.load: lam * self.factor}

    def state(self, x, lam):
        """(q full, loads) of unknowns x at parameter lam."""
        q = self.scene.reference_state()
        q[self.scene.free] = x
        return q, self.loads(lam)

    def x_of(self, q) -> np.ndarray:
        return q[self.scene.free].copy()

    def lam_of(self, loads) -> float:
        return loads[self.load] / self.factor

    def evaluate(self, x, lam, order=2, with_floor=False):
        """(residual, Jacobian) at (x, lam); with ``with_floor`` also the residual's rounding floor."""
        q, loads = self.state(x, lam)
        ev = self.scene.evaluate(q, loads, order)
        return (ev.residual, ev.stiffness, ev.residual_floor) if with_floor else (ev.residual, ev.stiffness)

    def dF_dlam(self, x, lam):
        q, loads = self.state(x, lam)
        return self.scene.load_derivative(q, self.load, loads) * self.factor

    def inadmissible(self, x, lam):
        return self.scene.inadmissible(self.state(x, lam)[0])

    def factorise(self, J):
        """(a factorisation of the Jacobian J, one of K within it): made once per point and shared
        by the tangent and the stability computation."""
        lu = J.factor()
        return lu, lu

    def stability(self, K, x, lam, n_eigs, start=None, tol=1e-10, sweeps=40, lu=None):
        """(the n_eigs eigenvalues of K nearest zero, ascending; the negative count; their vectors;
        the whole iterated subspace, to warm-start the next point).

        ``tol`` bounds the change of the eigenvalue nearest zero relative to |K|; at most ``sweeps``
        inverse iterations; ``lu``, K's factorisation if already made. With constraints held by
        multipliers K is their saddle matrix: the count is that of K on the constraints' tangent
        space (the saddle's less one per multiplier, Haynsworth); the eigenvalues are the saddle's
        (they vanish where the constrained stiffness is singular).
        """
        if lu is None:
            lu = K.factor()
        eigs, vectors, subspace = eigenvalues_near_zero(K, n_eigs, start, lu, tol, max_iterations=sweeps,
                                                        subspace=True)
        negative = getattr(lu, "negative", None)          # the band factorisations carry the inertia
        negative = K.negative_count() if negative is None else negative
        return eigs, negative - self.multipliers, vectors, subspace

    def measures(self, x, lam) -> dict:
        q, loads = self.state(x, lam)
        return {"pressure": loads.get("pressure", 0.0), "voltage": loads.get("voltage", 0.0),
                "E_hat": self.scene.e_hat(loads.get("voltage", 0.0)), **self.scene.measures(q, loads),
                **failure_margins(self.scene, q, loads)}

    def unknowns(self, q, loads) -> tuple:
        """(x, lam) of the full state q [m] under ``loads`` (resolved)."""
        return self.x_of(q), self.lam_of(loads)

    def start_loads(self, loads: dict) -> dict:
        """The loads to solve the first point of a branch at, from the scene's (resolved) loads."""
        if self.scene.start_guess is not None and all(v == 0 for v in loads.values()):
            # a flat plate is singular at rest: start on the branch at a small load
            lam = 1e-3 * self.lam_scale * (1 if self.control != "E_hat" else 0.1)
            return self.loads(lam)
        return loads

    def stiffness(self, J):
        """K within the Jacobian J (with the rows of any rigid body)."""
        return J

    def null_mode_borders(self, x, lam, J) -> list:
        """The vectors a null vector of K must be orthogonal to for the tangent to be free along
        it: dR/dlambda."""
        return [self.dF_dlam(x, lam)]

    def is_limit_point(self, coupling: float, turned: bool) -> bool:
        """Whether a critical point is a limit point (else a bifurcation point): the parameter
        turned back. The ``coupling`` |phi0 . dR/dlambda| (normalised) does not decide: on a mesh
        modes the continuum separates by symmetry couple to the load at discretisation order."""
        return turned

    def point_measures(self, p) -> dict:
        """The measures at point ``p`` (cached on it)."""
        if p.measured is None:
            p.measured = self.measures(p.x, p.lam)
        return p.measured

    def output(self, p, name: str) -> float:
        """The output ``name`` at point ``p``: the parameter ('lam' or the control) or a measure."""
        if name in ("lam", self.control):
            return p.lam
        m = self.point_measures(p)
        if name not in m:
            raise SnapmemError(f"until {name!r}: unknown output; allowed: {', '.join(k for k in m if k != 'taut')}")
        return float(m[name])



class VolumeProblem(LoadProblem):
    """Volume control: x = (free dofs, pressure), parameter V0, equations R = 0 and V(q) = V0.

    Stability is that of K on the tangent space of V = const: by Haynsworth's inertia formula
    the constrained negative count is neg(K) - 1 if g^T K^-1 g < 0 (g = grad V), else neg(K).
    The Jacobian is K bordered by grad V, so the parameter turning back does not make K singular.
    """

    jacobian_is_stiffness = False

    def __init__(self, scene: Scene):
        super().__init__(scene, "pressure")
        self.control = "volume"
        L = scene.meridian.size
        self.p_scale = self.lam_scale
        self.x_weight = np.append(self.x_weight, 1.0 / self.p_scale ** 2)
        v0 = abs(scene.volume(scene.reference_state()))
        # a balloon's volume grows ~ lam^3: ten reference volumes keep the state part of the
        # arclength in charge of the step, as it is under pressure control
        self.lam_scale = 10.0 * (v0 if v0 > 0 else L ** 3)

    @property
    def n(self) -> int:
        return self.scene.n_free + 1

    def state(self, x, lam):
        q = self.scene.reference_state()
        q[self.scene.free] = x[:-1]
        return q, {**self.base, "pressure": float(x[-1])}

    def x_of(self, q, pressure=0.0):
        return np.append(q[self.scene.free], pressure)

    def lam_of(self, loads) -> float:
        raise SnapmemError("volume control: the volume is an output; start from a state")

    def evaluate(self, x, lam, order=2, with_floor=False):
        q, loads = self.state(x, lam)
        ev = self.scene.evaluate(q, loads, order)
        g = -self.scene.load_derivative(q, "pressure", loads)                     # grad V (free)
        F = np.append(ev.residual, self.scene.volume(q) - lam)
        J = None if order < 2 else BorderedMatrix(ev.stiffness, -g, g, [[0.0]])
        return (F, J, ev.residual_floor) if with_floor else (F, J)

    def dF_dlam(self, x, lam):
        d = np.zeros(self.n)
        d[-1] = -1.0
        return d

    def factorise(self, J):
        inner = J.A.factor()
        return J.factor(inner), inner

    def stability(self, J, x, lam, n_eigs, start=None, tol=1e-10, sweeps=40, lu=None):
        K = J.A
        if lu is None:
            lu = K.factor()
        eigs, neg, vectors, subspace = super().stability(K, x, lam, n_eigs, start, tol, sweeps, lu)
        g = J.C[:, 0]
        if g @ lu.solve(g) < 0:
            neg -= 1
        return eigs, neg, vectors, subspace

    def unknowns(self, q, loads) -> tuple:
        return self.x_of(q, loads["pressure"]), self.scene.volume(q)

    def start_loads(self, loads: dict) -> dict:
        return loads

    def stiffness(self, J):
        return J.A

    def null_mode_borders(self, x, lam, J) -> list:
        """grad V (dR/dlambda has no component on the state)."""
        return [J.C[:, 0]]

    def is_limit_point(self, coupling: float, turned: bool) -> bool:
        """Under volume control by the turning alone: a limit point if the volume turned back."""
        return turned



#: Functions (scene, control) -> problem or None, asked first: scenes of another kind (several
#: membranes and their chambers, snapmem.continuation.chambers) register theirs here on import.
PROBLEM_FACTORIES: list = []


def make_problem(scene: Scene, control: str) -> LoadProblem:
    """The problem of tracing ``scene`` in ``control`` (one of :data:`CONTROLS`, or a control a
    factory of :data:`PROBLEM_FACTORIES` takes)."""
    for factory in PROBLEM_FACTORIES:
        problem = factory(scene, control)
        if problem is not None:
            return problem
    if control not in CONTROLS:
        raise SnapmemError(f"control = {control!r}: must be one of {', '.join(CONTROLS)}")
    if control == "volume":
        if "pressure" not in scene.loads:
            raise SnapmemError(f"control = 'volume': scene {scene.name!r} has no pressure term")
        return VolumeProblem(scene)
    return LoadProblem(scene, control)


class ProblemsByValue:
    """``make_problem(scene_at(v), control)`` for a second parameter v, the last few kept (a curve's
    Newton iteration asks for v and v +- h at every step)."""

    def __init__(self, scene_at, control: str, keep: int = 16):
        self.scene_at, self.control, self.keep = scene_at, control, keep
        self._problems: dict = {}

    def __call__(self, v):
        if v not in self._problems:
            if len(self._problems) > self.keep:
                self._problems.clear()
            self._problems[v] = make_problem(self.scene_at(v), self.control)
        return self._problems[v]
