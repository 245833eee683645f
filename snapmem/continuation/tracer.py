"""Pseudo-arclength continuation of equilibria, their stability, and their critical points.

A branch is traced in a control parameter lambda: a load (``pressure`` [Pa], ``voltage`` [V],
or the normalised ``E_hat``), or the enclosed ``volume`` [m^3] (then the pressure is an unknown,
the Lagrange multiplier of the volume constraint, and pressure maxima are passed without a jump).

Each step predicts along the unit tangent and corrects with Newton on the extended system
[R(x, lambda); <t, (x, lambda) - (x0, lambda0)> - ds] = 0, whose Jacobian is K bordered by
dR/dlambda and the tangent: it stays regular at a fold where K is singular, and is solved by
block elimination with refinement (snapmem.kernels.banded.BorderedMatrix), so every solve is O(N).

At every accepted point the smallest eigenvalues of K on the free degrees of freedom and their
negative count (the inertia index) are recorded; one factorisation of K serves the tangent and
them. When the count changes between two points, the critical point is located by Brent's
method on the arclength: where the parameter turns back (a limit point of a load) as the zero of
the tangent's parameter component, which vanishes exactly where K is singular and needs no
eigenvalues on the way; otherwise as the root of the eigenvalue that crossed zero, followed
along the arclength. Either locates it to near machine precision on the mesh; its null vector
phi0 classifies it (MODEL.md section 3): a limit point (LP) has phi0 . dR/dlambda != 0, a
bifurcation point (BP) has phi0 . dR/dlambda = 0.

Lengths in the arclength are scaled: state changes by L sqrt(N) (L the meridian size, so that
a uniform stretch of the whole membrane counts the same at any N), the parameter by its scale
(pressure mu H / L, voltage H sqrt(mu / eps), volume ten reference volumes, or 10 L^3).
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import asdict, dataclass, field
from typing import Callable, Mapping

import numpy as np
import pandas as pd
from scipy.optimize import brentq

from snapmem.kernels.banded import BorderedMatrix, eigenvalues_near_zero, scale_of
from snapmem.errors import SnapmemError, SolverError, check_int, check_real
from snapmem.solvers.newton import equilibrium
from snapmem.model.scene import Scene
from snapmem.threads import single_threaded

log = logging.getLogger(__name__)

CONTROLS = ("pressure", "voltage", "E_hat", "volume")


# ----------------------------------------------------------------------------------------------
# options and results
@dataclass(frozen=True)
class ContinuationOptions:
    """Options of :func:`trace`, with their defaults.

    Attributes
    ----------
    ds : float
        First step length (scaled arclength, dimensionless), default 0.05.
    ds_min, ds_max : float
        Step bounds, default 1e-6 and 0.3.
    max_steps : int
        Accepted steps at most, default 2000.
    newton_tol : float
        Corrector tolerance on max |R| relative to the scene's force scale, default 1e-10.
    max_corrector_iterations : int
        Default 8; more means the step is cut.
    target_iterations : int
        Corrector iterations aimed at; fewer grow the step, more shrink it. Default 3.
    max_angle : float
        Largest angle between consecutive tangents [rad] before a step is cut, default 0.3.
    n_eigs : int
        Eigenvalues nearest zero watched at every point, default 2 (the negative count comes
        from an LDL^T factorisation, not from these).
    stability : bool
        Compute eigenvalues and inertia at every point (default True).
    locate : bool
        Locate critical points precisely (default True).
    stop_at_first_limit : bool
        Stop the trace at the first limit point (default False).
    save_at : tuple of float
        Values of the control parameter at which points are located exactly (not interpolated).
    direction : int
        +1 to start with the parameter increasing, -1 decreasing.
    """

    ds: float = 0.05
    ds_min: float = 1e-6
    ds_max: float = 0.3
    max_steps: int = 2000
    newton_tol: float = 1e-10
    max_corrector_iterations: int = 8
    target_iterations: int = 3
    max_angle: float = 0.3
    n_eigs: int = 2
    stability: bool = True
    locate: bool = True
    stop_at_first_limit: bool = False
    save_at: tuple = ()
    direction: int = 1

    def __post_init__(self):
        check_real("ds", self.ds, minimum=0.0, min_inclusive=False)
        check_real("ds_min", self.ds_min, minimum=0.0, min_inclusive=False)
        check_real("ds_max", self.ds_max, minimum=self.ds_min)
        check_int("max_steps", self.max_steps, minimum=1)
        check_real("newton_tol", self.newton_tol, minimum=0.0, min_inclusive=False)
        check_int("max_corrector_iterations", self.max_corrector_iterations, minimum=1)
        check_int("target_iterations", self.target_iterations, minimum=1)
        check_real("max_angle", self.max_angle, minimum=0.0, min_inclusive=False, maximum=math.pi)
        check_int("n_eigs", self.n_eigs, minimum=1)
        if self.direction not in (1, -1):
            raise SnapmemError(f"direction = {self.direction!r}: must be +1 or -1")
        object.__setattr__(self, "save_at", tuple(check_real("save_at", v) for v in self.save_at))


@dataclass
class Point:
    """One equilibrium on a branch: the state, the control value and what was measured there."""

    x: np.ndarray            # unknowns of the problem (free dofs, + pressure under volume control)
    lam: float               # control parameter
    tangent: np.ndarray | None = None   # unit tangent (x part, lambda part), shape (n + 1,)
    eigs: np.ndarray | None = None
    negative: int | None = None
    s: float = 0.0           # arclength from the start
    ds: float = 0.0          # the step that reached it
    iterations: int = 0      # corrector iterations
    kind: str = ""           # '', 'LP', 'BP', 'SAVE', 'END'
    located: bool = False
    coupling: float = float("nan")   # |phi0 . dR/dlambda| / (|phi0| |dR/dlambda|) at a critical point
    vectors: np.ndarray | None = field(default=None, repr=False)   # eigenvectors of ``eigs``
    subspace: np.ndarray | None = field(default=None, repr=False)  # the eigen-iteration's last subspace
    measured: dict | None = field(default=None, repr=False)        # cache of the problem's measures

    @property
    def test_value(self) -> float:
        return float("nan") if self.eigs is None else float(self.eigs[0])


@dataclass
class Branch:
    """A traced branch: the points table, the critical points and everything to restart from.

    Attributes
    ----------
    table : pandas.DataFrame
        One row per point (accepted steps, located critical points, save_at points), in
        arclength order: pressure, voltage, E_hat, volume, u_max, stretch_max, min_eig,
        negative_eigs, stable, min_tension, taut, point ('' or 'LP' or 'BP'), and the scene's probes.
    points : pandas.DataFrame
        The critical points: ``kind`` and the same quantities at the located point, ``located``
        (False if only bracketed) and ``coupling`` (|phi0 . dR/dlambda| normalised).
    rejections : pandas.DataFrame
        Every rejected or cut step: step, s, ds, reason.
    status : str
        Why the trace stopped.
    """

    scene: Scene
    control: str
    table: pd.DataFrame
    points: pd.DataFrame
    rejections: pd.DataFrame
    status: str
    states: list = field(repr=False, default_factory=list)
    stats: dict = field(default_factory=dict)

    def limit_points(self) -> pd.DataFrame:
        return self.points[self.points["kind"] == "LP"]

    def save(self, path) -> None:
        """Save every point's state, tangent, inertia and step as a compressed .npz (no pickle).

        Arrays: ``x`` (M, n) unknowns, ``q`` (M, 2N) full states, ``lam`` (M,), ``tangent``
        (M, n + 1; NaN where none), ``negative_eigs`` (M,), ``s``, ``ds``, ``kind`` (M,) str,
        and ``meta``, a JSON string with the scene name and parameters and the control.
        """
        M = len(self.states)
        n = self.states[0].x.size if M else 0
        tangent = np.full((M, n + 1), np.nan)
        for i, p in enumerate(self.states):
            if p.tangent is not None:
                tangent[i] = p.tangent
        problem = make_problem(self.scene, self.control)
        from snapmem.io.results import write_npz
        write_npz(
            path, x=np.array([p.x for p in self.states]), lam=np.array([p.lam for p in self.states]),
            q=np.array([problem.state(p.x, p.lam)[0] for p in self.states]), tangent=tangent,
            negative_eigs=np.array([-1 if p.negative is None else p.negative for p in self.states]),
            s=np.array([p.s for p in self.states]), ds=np.array([p.ds for p in self.states]),
            kind=np.array([p.kind for p in self.states], dtype=str),
            meta=np.array(json.dumps({"scene": self.scene.name, "parameters": _jsonable(self.scene.parameters),
                                      "control": self.control})))


def load_points(path) -> dict:
    """Read a branch file written by :meth:`Branch.save` (no pickle); returns its arrays and meta."""
    from snapmem.errors import read_npz
    out = read_npz(path, "branch file", required=("x", "lam", "meta"))
    out["meta"] = json.loads(str(out["meta"]))
    return out


def _jsonable(d):
    return {k: (v if isinstance(v, (str, int, float, bool)) or v is None else str(v)) for k, v in d.items()}


# ----------------------------------------------------------------------------------------------
# problems: what is continued
class LoadProblem:
    """Equilibria R(q; loads) = 0 with one load as the parameter: x = free dofs."""

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
        lu = J.lu()
        return lu, lu

    def stability(self, K, x, lam, n_eigs, start=None, tol=1e-10, sweeps=40, lu=None):
        """(the n_eigs eigenvalues of K nearest zero, ascending; the negative count; their vectors;
        the whole iterated subspace, to warm-start the next point).

        ``tol`` bounds the change of the eigenvalue nearest zero relative to |K|; at most ``sweeps``
        inverse iterations; ``lu``, K's factorisation if already made.
        """
        if lu is None:
            lu = K.lu()
        eigs, vectors, subspace = eigenvalues_near_zero(K, n_eigs, start, lu, tol, max_iterations=sweeps,
                                                        subspace=True)
        negative = getattr(lu, "negative", None)          # the band factorisations carry the inertia
        return eigs, K.negative_count() if negative is None else negative, vectors, subspace

    def measures(self, x, lam) -> dict:
        q, loads = self.state(x, lam)
        return {"pressure": loads.get("pressure", 0.0), "voltage": loads.get("voltage", 0.0),
                "E_hat": self.scene.e_hat(loads.get("voltage", 0.0)), **self.scene.measures(q, loads)}


class VolumeProblem(LoadProblem):
    """Volume control: x = (free dofs, pressure), parameter V0, equations R = 0 and V(q) = V0.

    Stability is that of K on the tangent space of V = const: by Haynsworth's inertia formula
    the constrained negative count is neg(K) - 1 if g^T K^-1 g < 0 (g = grad V), else neg(K).
    """

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
        inner = J.A.lu()
        return J.lu(inner), inner

    def stability(self, J, x, lam, n_eigs, start=None, tol=1e-10, sweeps=40, lu=None):
        K = J.A
        if lu is None:
            lu = K.lu()
        eigs, neg, vectors, subspace = super().stability(K, x, lam, n_eigs, start, tol, sweeps, lu)
        g = J.C[:, 0]
        if g @ lu.solve(g) < 0:
            neg -= 1
        return eigs, neg, vectors, subspace



def make_problem(scene: Scene, control: str):
    if control not in CONTROLS:
        raise SnapmemError(f"control = {control!r}: must be one of {', '.join(CONTROLS)}")
    if control == "volume":
        if "pressure" not in scene.loads:
            raise SnapmemError(f"control = 'volume': scene {scene.name!r} has no pressure term")
        return VolumeProblem(scene)
    return LoadProblem(scene, control)


# ----------------------------------------------------------------------------------------------
# the predictor-corrector
class _Tracer:
    def __init__(self, problem, options: ContinuationOptions, scene: Scene):
        self.pb, self.opt, self.scene = problem, options, scene
        self.tol = options.newton_tol * scene.force_scale
        self.wx, self.wl = problem.x_weight, 1.0 / problem.lam_scale ** 2
        self.newton_iterations = 0
        self.evaluations = 0

    def inner(self, a, b):
        return float(a[:-1] @ (self.wx * b[:-1]) + self.wl * a[-1] * b[-1])

    def tangent(self, x, lam, J, previous: np.ndarray | None, lu=None):
        """Unit tangent at (x, lam), oriented along ``previous`` (or the chosen direction);
        ``lu``: J's factorisation if already made."""
        Fl = self.pb.dF_dlam(x, lam)
        if previous is None:
            row, corner = np.zeros(x.size), [[1.0]]
        else:
            row, corner = self.wx * previous[:-1], [[self.wl * previous[-1]]]
        M = BorderedMatrix(J, Fl, row, corner)
        lu = M.lu(lu)
        if lu.singular:
            raise SolverError("singular extended Jacobian: cannot compute the tangent")
        rhs = np.zeros(x.size + 1)
        rhs[-1] = 1.0
        t = lu.solve(rhs)
        t /= math.sqrt(self.inner(t, t))
        if previous is None:
            t *= self.opt.direction
        return t

    def correct(self, base: Point, s: float, guess: tuple | None = None):
        """Newton on the arclength system from the predictor base + s t (or from ``guess``, an
        (x, lam) nearer the solution). Returns (Point, J) or (None, why)."""
        t = base.tangent
        x, lam = (base.x + s * t[:-1], base.lam + s * t[-1]) if guess is None else guess
        row, corner = self.wx * t[:-1], [[self.wl * t[-1]]]
        last_step = np.inf
        for it in range(self.opt.max_corrector_iterations + 1):
            why = self.pb.inadmissible(x, lam)
            if why is not None:
                return None, f"left the model's domain ({why})"
            F, J, floor = self.pb.evaluate(x, lam, with_floor=True)
            self.evaluations += 1
            g = self.inner(t, np.append(x - base.x, lam - base.lam)) - s
            norm = float(np.max(np.abs(F)))
            if not np.isfinite(norm):
                return None, "residual not finite"
            tol = max(self.tol, floor)
            # at the rounding floor of a stiff state (a law near its lock): the last step was at
            # the rounding of x and the residual is within 1e3 of the tolerance
            at_rounding = last_step <= 1e-10 * np.max(np.abs(x)) and norm <= 1e3 * tol
            if (norm <= tol or at_rounding) and abs(g) <= 1e-12 * max(abs(s), 1e-300) + 1e-14:
                return Point(x, lam, iterations=it), J
            if it == self.opt.max_corrector_iterations:
                return None, f"corrector did not converge in {it} iterations (|R| = {norm:.2e})"
            M = BorderedMatrix(J, self.pb.dF_dlam(x, lam), row, corner)
            lu = M.lu()
            if lu.singular:
                return None, "singular extended Jacobian"
            d = lu.solve(-np.append(F, g))
            self.newton_iterations += 1
            x, lam = x + d[:-1], lam + d[-1]
            last_step = float(np.max(np.abs(d[:-1])))
        return None, "corrector failed"

    def finish(self, p: Point, J, previous: Point | None, tangent: bool = True, precise: bool = False,
               stability: bool = True):
        """Tangent (oriented along the previous point's) and stability at a converged point.

        One factorisation of J serves both. At ordinary points at most three inverse iterations
        from the previous point's subspace (min_eig is reported there, measured within 2e-8 |K|
        on the balloon's curves; the inertia, which decides stability, is exact from LDL^T); when
        ``precise`` (locating a critical point) until the Ritz values move by less than 1e-9 |K|
        or reach rounding.
        """
        stability = self.opt.stability and stability
        if not (tangent or stability):
            return p
        lu, lu_K = self.pb.factorise(J)
        if stability:
            start = None if previous is None else (previous.subspace if previous.subspace is not None
                                                   else previous.vectors)
            try:
                p.eigs, p.negative, p.vectors, p.subspace = self.pb.stability(
                    J, p.x, p.lam, self.opt.n_eigs, start, tol=1e-9 if precise else 1e-6,
                    sweeps=40 if precise else 3, lu=lu_K)
            except np.linalg.LinAlgError as exc:
                raise SolverError(f"stability: {exc}") from None
        if tangent:
            p.tangent = self.tangent(p.x, p.lam, J, None if previous is None else previous.tangent, lu)
            if previous is None and p.eigs is not None:
                self._drop_null_modes(p, J)
        return p

    def _drop_null_modes(self, p: Point, J):
        """At a degenerate start the tangent is not unique: K has a null vector that no border
        couples to (dR/dlambda, or grad V under volume control), so the extended Jacobian is
        singular too and the branch bifurcates there (a slack shell at rest). The solve then
        returns rounding amplified along that vector; keep the tangent without it (the minimum-norm
        one, which continues the branch the load drives)."""
        volume = isinstance(self.pb, VolumeProblem)
        K = J.A if volume else J
        n = p.vectors.shape[0]
        borders = [self.pb.dF_dlam(p.x, p.lam)[:n]] + ([J.C[:, 0]] if volume else [])
        t = p.tangent.copy()
        singular = np.abs(p.eigs) <= 1e-10 * scale_of(K)
        for phi in p.vectors[:, singular].T:
            if all(abs(phi @ b) <= 1e-8 * np.linalg.norm(b) for b in borders):
                t[:n] -= (phi @ t[:n]) * phi
        if not np.array_equal(t, p.tangent):
            p.tangent = t / math.sqrt(self.inner(t, t))

    def point_at(self, base: Point, s: float, tangent: bool = True, precise: bool = True, stability: bool = True,
                 guess: tuple | None = None):
        """The converged point at arclength s from base (with eigenvalues), or raise SolverError."""
        p, J = self.correct(base, s, guess)
        if p is None:
            raise SolverError(f"corrector failed while locating: {J}")
        p.s = base.s + s
        return self.finish(p, J, base, tangent, precise, stability), J


@single_threaded
def trace(scene: Scene, control: str = "pressure", until: Mapping[str, float] | None = None,
          options: ContinuationOptions = ContinuationOptions(), start: tuple | None = None,
          progress: Callable[[Point, dict], None] | None = None) -> Branch:
    """Trace the equilibrium branch of ``scene`` in ``control`` by pseudo-arclength continuation.

    Parameters
    ----------
    scene : Scene
        The scene; its loads give the start (e.g. pressure = 0) for load controls.
    control : {'pressure', 'voltage', 'E_hat', 'volume'}
        The parameter varied.
    until : mapping NAME -> value, optional
        Stop when any output column (e.g. ``stretch_max``, ``pressure``, ``u_max``) reaches the
        value, the last point located on it exactly. Default: none (``max_steps`` stops it).
    options : ContinuationOptions
    start : (q, loads), optional
        Start from this state (e.g. a row of a saved branch) instead of solving for one.
    progress : callable, optional
        Called as progress(point, row) after every accepted point.

    Returns
    -------
    Branch
    """
    pb = make_problem(scene, control)
    until = dict(until or {})
    tracer = _Tracer(pb, options, scene)
    x0, lam0 = _start(scene, pb, control, start)
    F, J = pb.evaluate(x0, lam0)
    if np.max(np.abs(F)) > 1e3 * tracer.tol:
        raise SolverError(f"start state is not an equilibrium (max |R| = {np.max(np.abs(F)):.3e})")
    first = tracer.finish(Point(x0, lam0), J, None)
    points = [first]
    rejections = []
    critical = []
    ds = options.ds
    status = f"max_steps ({options.max_steps}) reached"
    save_at = sorted(options.save_at)
    for step in range(options.max_steps):
        base = points[-1]
        p, J = tracer.correct(base, ds)
        reason = J if p is None else None
        if p is not None:
            p.s, p.ds = base.s + ds, ds
            try:
                tracer.finish(p, J, base)
            except SolverError as exc:
                reason = str(exc)
        if reason is None:
            angle = math.acos(max(-1.0, min(1.0, tracer.inner(base.tangent, p.tangent))))
            if angle > options.max_angle and ds > options.ds_min:
                reason = f"tangent turned by {angle:.3f} rad > max_angle"
            elif (options.stability and abs(p.negative - base.negative) >= 2 and ds > options.ds_min):
                reason = f"negative eigenvalue count jumped {base.negative} -> {p.negative}: may straddle two critical points"
        if reason is not None:
            rejections.append({"step": step, "s": base.s, "ds": ds, "reason": reason})
            log.info("step %d cut (ds = %.3g): %s", step, ds, reason)
            if ds <= options.ds_min:
                status = f"step too small (ds = {options.ds_min:g}) after: {reason}"
                break
            ds = max(0.5 * ds, options.ds_min)
            continue
        # a critical point between base and p?
        new_critical = []
        if options.stability and p.negative != base.negative:
            new_critical.append(_locate_critical(tracer, base, p))
        elif options.stability and len(points) >= 2:
            new_critical.extend(_touching(tracer, points[-2], base, p))
        # exact points on save_at values and at the until values
        inserts = [c for c in new_critical if c is not None]
        for value in save_at:
            if (base.lam - value) * (p.lam - value) < 0:
                q = _locate_value(tracer, base, p, lambda pt, s: pt.lam - value, "SAVE", needs_eigenvalues=False)
                if q is not None:
                    inserts.append(q)
        stop_point, stop_name = None, None
        for name, value in until.items():
            f0 = _output(pb, base, name) - value
            f1 = _output(pb, p, name) - value
            if f0 * f1 <= 0 and f1 != f0:
                stop_point = _locate_value(tracer, base, p, lambda pt, s, n=name, v=value: _output(pb, pt, n) - v, "END",
                                           needs_eigenvalues=False)
                stop_name = f"{name} reached {value:g}"
                break
        if stop_point is not None:
            inserts = [c for c in inserts if c.s < stop_point.s]
            inserts.append(stop_point)
            points.extend(sorted(inserts, key=lambda c: c.s))
            critical.extend(c for c in inserts if c.kind in ("LP", "BP"))
            status = stop_name
            break
        points.extend(sorted(inserts, key=lambda c: c.s))
        critical.extend(c for c in inserts if c.kind in ("LP", "BP"))
        points.append(p)
        if progress is not None:
            progress(p, {})
        if options.stop_at_first_limit and any(c.kind == "LP" for c in inserts):
            status = "stopped at the first limit point"
            break
        # adapt the step from the corrector's effort
        factor = (options.target_iterations / max(p.iterations, 1)) ** 0.5
        ds = min(options.ds_max, max(options.ds_min, ds * min(2.0, max(0.5, factor))))
    return _assemble(scene, control, pb, points, critical, rejections, status, tracer)


def _start(scene, pb, control, start):
    if start is not None:
        q, loads = start
        loads = scene.resolve_loads(loads)
        if control == "volume":
            return pb.x_of(np.asarray(q, float), loads["pressure"]), scene.volume(np.asarray(q, float))
        return pb.x_of(np.asarray(q, float)), pb.lam_of(loads)
    loads = scene.resolve_loads(None)
    if control == "volume":
        eq = equilibrium(scene, loads)
        if not eq.converged:
            raise SolverError(f"no start equilibrium: {eq.report.reason}")
        return pb.x_of(eq.q, loads["pressure"]), scene.volume(eq.q)
    if scene.start_guess is not None and all(v == 0 for v in loads.values()):
        # a flat plate is singular at rest: start on the branch at a small load
        lam = 1e-3 * pb.lam_scale * (1 if control != "E_hat" else 0.1)
        loads = pb.loads(lam)
    eq = equilibrium(scene, loads)
    if not eq.converged:
        raise SolverError(f"no start equilibrium at {loads}: {eq.report.reason}")
    return pb.x_of(eq.q), pb.lam_of(loads)


def _measures(pb, p: Point) -> dict:
    if p.measured is None:
        p.measured = pb.measures(p.x, p.lam)
    return p.measured


def _output(pb, p: Point, name: str) -> float:
    if name in ("lam", pb.control):
        return p.lam
    m = _measures(pb, p)
    if name not in m:
        raise SnapmemError(f"until {name!r}: unknown output; allowed: {', '.join(k for k in m if k != 'taut')}")
    return float(m[name])


class _Found(Exception):
    """f is within its tolerance of zero at arclength offset ``s``."""

    def __init__(self, s: float):
        super().__init__(s)
        self.s = s


def _locate_value(tracer, base: Point, p: Point, f, kind: str, needs_eigenvalues: bool = True,
                  ftol: float = 0.0):
    """The point between base and p where f(point, s) = 0, by Brent's method on the arclength s
    from base (p is at s = ds; f is evaluated there and at base from the points themselves),
    stopping at s to 1e-13 ds or where |f| <= ``ftol`` (the rounding of f: Brent's method would
    go on bisecting noise there).

    Every point computed on the way gets its tangent, and the next one starts its corrector from
    the nearest point along that tangent (one or two iterations instead of three from base).
    Each starts its eigenvalue iteration (where ``needs_eigenvalues``) from the subspace of the
    last point computed, so it converges in a sweep or two. The located point is the one Brent's
    method evaluated last if that is where it stopped, else computed anew.
    """
    ds = p.s - base.s
    cache = {0.0: (base, None), ds: (p, None)}
    last = [base]

    def g(s):
        if s not in cache:
            cache[s] = tracer.point_at(_with_vectors(base, last[0]), s, stability=needs_eigenvalues,
                                       guess=_guess(tracer, base, cache, s))
            last[0] = cache[s][0]
        value = f(cache[s][0], s)
        if abs(value) <= ftol and 0.0 < s < ds:
            raise _Found(s)
        return value

    try:
        try:
            s = brentq(g, 0.0, ds, xtol=1e-13 * ds, rtol=4 * np.finfo(float).eps, maxiter=60)
        except _Found as found:
            s = found.s
        pt, J = cache.get(s, (None, None))
        if J is None:
            pt = tracer.point_at(_with_vectors(base, last[0]), s, guess=_guess(tracer, base, cache, s))[0]
        elif not needs_eigenvalues and tracer.opt.stability:
            tracer.finish(pt, J, _with_vectors(base, last[0]), tangent=False, precise=True)
    except (SolverError, ValueError, RuntimeError) as exc:      # RuntimeError: Brent's iteration limit
        log.warning("could not locate %s point: %s", kind, exc)
        return None
    pt.kind, pt.located = kind, True
    return pt


def _guess(tracer, base: Point, computed: dict, s: float):
    """Start of the corrector for the point at arclength s from base: along the tangent of the
    nearest point computed ({offset: (point, J)}), onto the arclength hyperplane of s."""
    near = min(computed, key=lambda t: abs(t - s))
    q = computed[near][0]
    step = (s - near) / tracer.inner(base.tangent, q.tangent)
    return q.x + step * q.tangent[:-1], q.lam + step * q.tangent[-1]


def _with_vectors(base: Point, donor: Point) -> Point:
    """``base`` with the eigenvectors of ``donor`` (a warm start for the eigenvalue iteration)."""
    if donor is base or donor.vectors is None:
        return base
    clone = Point(base.x, base.lam, base.tangent, base.eigs, base.negative, base.s, base.ds)
    clone.vectors, clone.subspace = donor.vectors, donor.subspace
    return clone


def _crossing_index(pt: Point, rising_side_positive: bool):
    """Index in pt.eigs of the eigenvalue nearest zero on one side (None if the set has none)."""
    pick = np.flatnonzero(pt.eigs >= 0) if rising_side_positive else np.flatnonzero(pt.eigs < 0)
    if pick.size == 0:
        return None
    return pick[np.argmin(pt.eigs[pick])] if rising_side_positive else pick[np.argmax(pt.eigs[pick])]


def _locate_critical(tracer, base: Point, p: Point):
    """Locate the critical point where an eigenvalue's sign change altered the inertia between base and p.

    Where the parameter turns back between them, it is the zero of the tangent's parameter
    component. Otherwise it is the zero of the eigenvalue that crossed: at the two ends the
    inertia says which one (the smallest non-negative one on the side with fewer negative
    eigenvalues, the largest negative one on the other); inside the bracket it is followed by
    continuity of its eigenvector from the nearest point already computed: there the inertia
    count is unreliable within rounding of a singular K.
    """
    located = None
    rising = p.negative > base.negative
    i_base, i_p = _crossing_index(base, rising), _crossing_index(p, not rising)
    if tracer.opt.locate and i_base is not None and i_p is not None and base.vectors is not None:
        ds = p.s - base.s
        tracked = {0.0: base.vectors[:, i_base], ds: p.vectors[:, i_p]}
        ends = {0.0: float(base.eigs[i_base]), ds: float(p.eigs[i_p])}

        def crossing(pt, s):
            if s in ends:
                return ends[s]
            nearest = min(tracked, key=lambda t: abs(t - s))
            i = int(np.argmax(np.abs(pt.vectors.T @ tracked[nearest])))
            tracked[s] = pt.vectors[:, i]
            return float(pt.eigs[i])

        if base.tangent[-1] * p.tangent[-1] < 0 and not isinstance(tracer.pb, VolumeProblem):
            # a limit point of the parameter: there K is singular and the tangent's parameter
            # component vanishes, a simple zero that needs no eigenvalues on the way
            scale = math.sqrt(tracer.wl)                # the parameter component of the unit tangent
            located = _locate_value(tracer, base, p, lambda pt, s: scale * pt.tangent[-1], "critical",
                                    needs_eigenvalues=False, ftol=1e-12)
        else:
            located = _locate_value(tracer, base, p, crossing, "critical")
        if located is None:
            located = _polish_critical(tracer, base, p, base.vectors[:, i_base] + p.vectors[:, i_p] * np.sign(base.vectors[:, i_base] @ p.vectors[:, i_p]))
    if located is None:       # bracketed only: report the nearer end
        located = Point(p.x, p.lam, p.tangent, p.eigs, p.negative, p.s, p.ds, 0)
    located.kind = _classify(tracer, located, base, p)
    located.negative = max(base.negative, p.negative)
    return located


def _polish_critical(tracer, base: Point, p: Point, phi: np.ndarray):
    """Where following the crossing eigenvalue fails (modes crowding near a bifurcation), locate
    the singular point by Newton on the minimally extended system [R = 0, g = 0] from the
    bracket, as fold curves do. Accepted if it lands within the bracket."""
    if isinstance(tracer.pb, VolumeProblem):
        return None
    result = _fold_newton(tracer.pb, tracer.scene, 0.5 * (base.x + p.x), 0.5 * (base.lam + p.lam),
                          phi / np.linalg.norm(phi), FoldOptions())
    if result is None:
        return None
    x, lam, _, _ = result
    span = np.append(p.x - base.x, p.lam - base.lam)
    where = tracer.inner(span, np.append(x - base.x, lam - base.lam)) / tracer.inner(span, span)
    if not -0.25 <= where <= 1.25:
        log.warning("critical point polished outside its bracket (at %.3g of it): not used", where)
        return None
    _, J = tracer.pb.evaluate(x, lam)
    pt = Point(x, lam, s=base.s + where * (p.s - base.s))
    tracer.finish(pt, J, _with_vectors(base, p), tangent=True, precise=True)
    pt.kind, pt.located = "critical", True
    return pt


def _classify(tracer, c: Point, base: Point, p: Point) -> str:
    """LP if the null vector couples to dR/dlambda (or the parameter turns back), else BP."""
    pb = tracer.pb
    volume = isinstance(pb, VolumeProblem)
    if c.located and c.vectors is not None:      # K's vector nearest zero, converged at the point
        phi = c.vectors[:, np.argmin(np.abs(c.eigs))]
    else:
        _, J = pb.evaluate(c.x, c.lam)
        K = J.A if isinstance(J, BorderedMatrix) else J
        lu = K.lu()
        phi = np.random.default_rng(0).normal(size=K.n)
        if not lu.singular:
            for _ in range(3):                       # inverse iteration: K is (nearly) singular here
                phi = lu.solve(phi)
                phi /= np.linalg.norm(phi)
    Fl = pb.dF_dlam(c.x, c.lam)[: phi.size]
    c.coupling = abs(float(phi @ Fl)) / (np.linalg.norm(phi) * np.linalg.norm(Fl) + 1e-300)
    turned = base.tangent[-1] * p.tangent[-1] < 0
    if volume:                                   # volume control: classify by the turning
        return "LP" if turned else "BP"
    return "LP" if (c.coupling > 1e-6 or turned) else "BP"


def _touching(tracer, a: Point, b: Point, c: Point):
    """Catch an eigenvalue that dips to zero and back between a and c without changing the count."""
    fa, fb, fc = a.test_value, b.test_value, c.test_value
    if not (b.negative == a.negative == c.negative and fb < fa and fb < fc):
        return []
    if b.negative > 0:                     # watch the lowest non-negative eigenvalue
        return []
    sa, sb, sc = a.s, b.s, c.s
    # parabola through the three points; its minimum
    A = np.array([[sa * sa, sa, 1], [sb * sb, sb, 1], [sc * sc, sc, 1]])
    try:
        qa, qb, qc = np.linalg.solve(A, [fa, fb, fc])
    except np.linalg.LinAlgError:
        return []
    if qa <= 0:
        return []
    s_min = -qb / (2 * qa)
    f_min = qc - qb * qb / (4 * qa)
    if f_min > 0 or not (sa < s_min < sc):
        return []
    log.info("an eigenvalue may touch zero near s = %.6g: checking", s_min)
    try:
        mid = tracer.point_at(b, s_min - sb)[0] if s_min > sb else tracer.point_at(a, s_min - sa)[0]   # its tangent classifies
    except SolverError:
        return []
    if mid.negative == b.negative:
        return []
    base = b if s_min > sb else a
    first = _locate_critical(tracer, base, mid)
    second = _locate_critical(tracer, mid, c) if s_min > sb else _locate_critical(tracer, mid, b)
    return [first, second]


def _assemble(scene, control, pb, points, critical, rejections, status, tracer) -> Branch:
    rows = []
    for p in points:
        m = _measures(pb, p)
        row = {"s": p.s, "control": p.lam, **m,
               "min_eig": p.test_value if p.eigs is None else float(p.eigs[0]),
               "negative_eigs": -1 if p.negative is None else int(p.negative),
               "stable": bool(p.negative == 0) if p.negative is not None else None,
               "point": p.kind if p.kind in ("LP", "BP") else "",
               "save_at": p.kind == "SAVE", "ds": p.ds, "iterations": p.iterations}
        rows.append(row)
    table = pd.DataFrame(rows)
    crit_rows = []
    for c in critical:
        m = _measures(pb, c)
        crit_rows.append({"kind": c.kind, "s": c.s, "control": c.lam, **m,
                          "min_eig": c.test_value, "located": c.located, "coupling": c.coupling})
    points_table = pd.DataFrame(crit_rows, columns=None if crit_rows else
                                ["kind", "s", "control", "pressure", "voltage", "E_hat", "volume", "u_max",
                                 "stretch_max", "min_tension", "taut", "min_eig", "located", "coupling"])
    stats = {"steps": int(sum(1 for p in points if p.kind == "")) - 1, "rejected": len(rejections),
             "newton_iterations": tracer.newton_iterations, "evaluations": tracer.evaluations}
    return Branch(scene, control, table, points_table,
                  pd.DataFrame(rejections, columns=["step", "s", "ds", "reason"]), status, points, stats)


# ----------------------------------------------------------------------------------------------
# two-parameter continuation of a limit point
@dataclass(frozen=True)
class FoldOptions:
    """Options of :func:`fold_curve`.

    Attributes
    ----------
    tol : float
        Newton tolerance on max |R| relative to the force scale, default 1e-10.
    max_iterations : int
        Newton iterations per value, default 15.
    max_refinements : int
        Times a failed increment of the second parameter is halved, default 6.
    trace_until : mapping
        Where the first trace (and a fallback trace) gives up looking for a limit point,
        default stretch_max = 12.
    """

    tol: float = 1e-10
    max_iterations: int = 15
    max_refinements: int = 6
    trace_until: tuple = (("stretch_max", 12.0),)


@single_threaded
def fold_curve(scene_at: Callable[[float], Scene], values, control: str = "pressure",
               options: FoldOptions = FoldOptions(), trace_options: ContinuationOptions = ContinuationOptions(),
               progress: Callable[[int, int], None] | None = None, start: tuple | None = None,
               return_folds: bool = False):
    """The curve of limit points of ``control`` as a second parameter runs through ``values``.

    The first limit point is found by tracing a branch; every next one by Newton on the
    minimally extended system [R(x, lam) = 0, g(x, lam) = 0] from the previous one, where g is
    the bordered test function ([[K, phi], [phi^T, 0]] [v; g] = [0; 1], zero exactly where K is
    singular) and dg/dx = -D3Pi[v, v, .] comes from a central difference of K(x + e v) v. So a
    limit-point map costs a few Newton steps per value, not a traced branch per value.

    Parameters
    ----------
    scene_at : callable
        value -> Scene (the same meridian node count for every value).
    values : sequence of float
        Values of the second parameter, in order.
    control : str
        The continuation parameter whose limit is followed ('pressure', 'voltage', 'E_hat').
    start : (value, x, lam, phi), optional
        A limit point already known at ``value`` of ``scene_at`` (from another fold curve's
        folds): the curve continues from it instead of tracing a first branch.
    return_folds : bool
        Also return the limit points found, {value: (value, x, lam, phi)}, to start other curves.

    Returns
    -------
    pandas.DataFrame
        One row per value: ``value``, ``limit`` (the control at the limit point), ``exists``,
        ``method`` ('fold' or 'trace'), ``iterations``, ``status``, and the branch measures at the
        limit point (pressure, voltage, E_hat, volume, u_max, stretch_max, min_tension, ...).
        With ``return_folds``: (table, folds).
    """
    if control == "volume":
        raise SnapmemError("control = 'volume': volume control has no limit points to follow")
    values = [check_real("value", v) for v in values]
    if not values:
        raise SnapmemError("values: need at least one value of the second parameter")
    rows, previous = [], ([start] if start is not None else [])   # previous: [(value, x, lam, phi)]
    references: dict = {}
    folds: dict = {}
    for i, value in enumerate(values):
        row = None
        if previous:
            row = _continue_fold(scene_at, previous, value, control, options, references)
        if row is None:
            row = _fold_by_trace(scene_at(value), control, options, trace_options)
        row["value"] = value
        rows.append(row)
        if row.pop("_fold", None) is not None and row["exists"]:
            previous.append((value, row.pop("_x"), row["limit"], row.pop("_phi")))
            folds[value] = previous[-1]
        else:
            row.pop("_x", None), row.pop("_phi", None)
        if progress is not None:
            progress(i + 1, len(values))
    table = pd.DataFrame(rows)
    table = table[["value", "limit", "exists", "method", "iterations", "status"]
                  + [c for c in table.columns if c not in ("value", "limit", "exists", "method", "iterations", "status")]]
    return (table, folds) if return_folds else table


def _fold_by_trace(scene, control, options, trace_options):
    opts = ContinuationOptions(**{**asdict(trace_options), "stop_at_first_limit": True, "save_at": ()})
    try:
        br = trace(scene, control, until=dict(options.trace_until), options=opts)
    except (SolverError, SnapmemError) as exc:
        return {"limit": float("nan"), "exists": False, "method": "trace", "iterations": 0,
                "status": f"trace failed: {exc}"}
    lps = br.limit_points()
    iterations = br.stats["newton_iterations"]
    if lps.empty:
        return {"limit": float("nan"), "exists": False, "method": "trace", "iterations": iterations,
                "status": f"no limit point ({br.status})"}
    pb = make_problem(scene, control)
    lp = next(p for p in br.states if p.kind == "LP")
    _, K = pb.evaluate(lp.x, lp.lam)
    phi = _null_vector(K)
    return {"limit": lp.lam, "exists": True, "method": "trace", "iterations": iterations,
            "status": "located", **pb.measures(lp.x, lp.lam), "_fold": True, "_x": lp.x, "_phi": phi}


def _null_vector(K):
    lu = K.lu()
    phi = np.random.default_rng(1).normal(size=K.n)
    if not lu.singular:
        for _ in range(3):
            phi = lu.solve(phi)
            phi /= np.linalg.norm(phi)
    return phi / np.linalg.norm(phi)


def _continue_fold(scene_at, previous, value, control, options, references, depth=0):
    v0, x0, lam0, phi = previous[-1]
    scene = scene_at(value)
    pb = make_problem(scene, control)
    ref_new = scene.reference_state()[scene.free]
    references[value] = ref_new
    if v0 not in references:
        old = scene_at(v0)
        references[v0] = old.reference_state()[old.free]
    ref_old = references[v0]
    x, lam = x0 - ref_old + ref_new, lam0
    if len(previous) >= 2:                        # secant predictor along the fold curve
        v1, x1, lam1, _ = previous[-2]
        f = (value - v0) / (v0 - v1)
        x, lam = x + f * (x0 - x1), lam + f * (lam0 - lam1)
    result = _fold_newton(pb, scene, x, lam, phi, options)
    if result is None:
        if depth >= options.max_refinements:
            return None
        mid = 0.5 * (v0 + value)
        row = _continue_fold(scene_at, previous, mid, control, options, references, depth + 1)
        if row is None or not row.get("exists"):
            return None
        extended = previous + [(mid, row["_x"], row["limit"], row["_phi"])]
        return _continue_fold(scene_at, extended, value, control, options, references, depth + 1)
    x, lam, phi_new, iterations = result
    return {"limit": lam, "exists": True, "method": "fold", "iterations": iterations, "status": "located",
            **pb.measures(x, lam), "_fold": True, "_x": x, "_phi": phi_new}


def _fold_newton(pb, scene, x, lam, phi, options):
    """Newton on [R; g] for the limit point near (x, lam); returns (x, lam, phi, iterations) or None."""
    tol = options.tol * scene.force_scale
    L = scene.meridian.size
    for it in range(options.max_iterations):
        if pb.inadmissible(x, lam) is not None:
            return None
        F, K = pb.evaluate(x, lam)
        border = BorderedMatrix(K, phi, phi, [[0.0]])
        lu = border.lu()
        if lu.singular:
            return None
        rhs = np.zeros(K.n + 1)
        rhs[-1] = 1.0
        sol = lu.solve(rhs)
        v, g = sol[:-1], sol[-1]
        eps = 1e-6 * L / max(np.max(np.abs(v)), 1e-300)
        Kv_plus = pb.evaluate(x + eps * v, lam)[1].matvec(v)
        Kv_minus = pb.evaluate(x - eps * v, lam)[1].matvec(v)
        g_x = -(Kv_plus - Kv_minus) / (2 * eps)                       # -D3Pi[v, v, .]
        dl = 1e-6 * max(abs(lam), pb.lam_scale)
        g_l = -(pb.evaluate(x, lam + dl)[1].matvec(v) - pb.evaluate(x, lam - dl)[1].matvec(v)) @ v / (2 * dl)
        Fl = pb.dF_dlam(x, lam)
        if not np.all(np.isfinite(F)):
            return None
        converged = np.max(np.abs(F)) <= tol
        J = BorderedMatrix(K, Fl, g_x, [[g_l]])
        lu = J.lu()
        if lu.singular:
            return None
        d = lu.solve(-np.append(F, g))
        if converged and abs(d[-1]) <= 1e-12 * max(abs(lam), pb.lam_scale):
            return x, lam, v / np.linalg.norm(v), it
        x, lam = x + d[:-1], lam + d[-1]
        if abs(d[-1]) > 0.5 * max(abs(lam), pb.lam_scale) or np.max(np.abs(d[:-1])) > 0.5 * L:
            return None                               # wandering off: refine the increment instead
    return None
