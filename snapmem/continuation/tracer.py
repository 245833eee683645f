"""Pseudo-arclength continuation of equilibria and their stability: the predictor-corrector loop.

A branch is traced in a control parameter lambda: a load (``pressure`` [Pa], ``voltage`` [V],
or the normalised ``E_hat``), or the enclosed ``volume`` [m^3] (then the pressure is an unknown,
the Lagrange multiplier of the volume constraint, and pressure maxima are passed without a jump).

Each step predicts along the unit tangent and corrects with Newton on the extended system
[R(x, lambda); <t, (x, lambda) - (x0, lambda0)> - ds] = 0, whose Jacobian is K bordered by
dR/dlambda and the tangent: it stays regular at a fold where K is singular, and is solved by
block elimination with refinement (snapmem.kernels.banded.BorderedMatrix), so every solve is O(N).

At every accepted point the smallest eigenvalues of K on the free degrees of freedom and their
negative count (the inertia index) are recorded; one factorisation of K serves the tangent and
them. After every accepted step the trace's events (snapmem.continuation.events) look between
the two points: critical points where the count changes (located and classified by
snapmem.continuation.locate), save_at values, until targets, and any event the caller passes.

Lengths in the arclength are scaled: state changes by L sqrt(N) (L the meridian size, so that
a uniform stretch of the whole membrane counts the same at any N), the parameter by its scale
(pressure mu H / L, voltage H sqrt(mu / eps), volume ten reference volumes, or 10 L^3).
"""

from __future__ import annotations

import logging
import math
from typing import Callable, Mapping, Sequence

import numpy as np

from snapmem.continuation.branch import Branch, Outcome, Point, PointKind
from snapmem.continuation.events import Event, Step, events_from
from snapmem.continuation.options import ContinuationOptions, resolve_options
from snapmem.continuation.problems import LoadProblem, make_problem
from snapmem.errors import SnapmemError, SolverError
from snapmem.io.table import Rows
from snapmem.kernels.banded import BorderedMatrix, scale_of
from snapmem.model.scene import Scene
from snapmem.solvers.newton import Equilibrium, solve
from snapmem.solvers.ramp import ramp
from snapmem.threads import single_threaded

log = logging.getLogger(__name__)


#: the kinds of point listed in a branch's points table (and named in its ``point`` column)
_SPECIAL = (PointKind.LP, PointKind.BP, PointKind.LE, PointKind.LT, PointKind.EB, PointKind.RU)


class Tracer:
    """The predictor-corrector of one branch: its problem ``pb``, options ``opt``, the arclength
    inner product and the work counters (Newton iterations, evaluations)."""

    def __init__(self, problem, options: ContinuationOptions, scene: Scene):
        options = resolve_options(options, scene)          # the scene's own defaults where unset
        self.pb, self.opt, self.scene = problem, options, scene
        self.tol = options.newton_tol * scene.force_scale
        self.wx, self.wl = problem.x_weight, 1.0 / problem.lam_scale ** 2
        self.newton_iterations = 0
        self.evaluations = 0

    def inner(self, a, b):
        """The arclength inner product of two (x, lambda) vectors (scaled, dimensionless)."""
        return float(a[:-1] @ (self.wx * b[:-1]) + self.wl * a[-1] * b[-1])

    def arclength_factor(self, J, Fl, row, corner, lu=None):
        """The factorisation of the arclength system [[J, Fl], [row^T, corner]]: the problem's own
        (its ``arclength_factor``, e.g. a chamber problem's single bordering of the band) if it
        has one, else J bordered (``lu``: J's factorisation, reused)."""
        own = getattr(self.pb, "arclength_factor", None)
        if own is not None:
            return own(J, Fl, row, corner, lu)
        return BorderedMatrix(J, Fl, row, corner).factor(lu)

    def tangent(self, x, lam, J, previous: np.ndarray | None, lu=None):
        """Unit tangent at (x, lam), oriented along ``previous`` (or the chosen direction);
        ``lu``: J's factorisation if already made."""
        Fl = self.pb.dF_dlam(x, lam)
        if previous is None:
            row, corner = np.zeros(x.size), [[1.0]]
        else:
            row, corner = self.wx * previous[:-1], [[self.wl * previous[-1]]]
        lu = self.arclength_factor(J, Fl, row, corner, lu)
        if lu.singular:
            raise SolverError("singular extended Jacobian: cannot compute the tangent")
        rhs = np.zeros(x.size + 1)
        rhs[-1] = 1.0
        t = lu.solve(rhs)
        t /= math.sqrt(self.inner(t, t))
        if previous is None:
            t *= self.opt.direction
        return t

    def correct(self, base: Point, s: float, guess: tuple | None = None, abandon_diverging: bool = False):
        """Newton on the arclength system from the predictor base + s t (or from ``guess``, an
        (x, lam) nearer the solution). Returns (Point, J) or (None, why). ``abandon_diverging``:
        give up at the first iterate whose max |R| exceeds the predictor's (the trace's steps,
        which are cut and tried again; not where a failure is final, locating or switching)."""
        t = base.tangent
        x, lam = (base.x + s * t[:-1], base.lam + s * t[-1]) if guess is None else guess
        row, corner = self.wx * t[:-1], [[self.wl * t[-1]]]
        last_step = np.inf
        first_norm = None
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
            if first_norm is None:
                first_norm = norm
            elif abandon_diverging and norm > first_norm and norm > 1e3 * tol:
                return None, f"corrector diverging: |R| = {norm:.2e} at iteration {it}, above the predictor's {first_norm:.2e}"
            lu = self.arclength_factor(J, self.pb.dF_dlam(x, lam), row, corner)
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
        K = self.pb.stiffness(J)
        n = p.vectors.shape[0]
        borders = [b[:n] for b in self.pb.null_mode_borders(p.x, p.lam, J)]
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
          progress: Callable[[Point, dict], None] | None = None, events: Sequence[Event] = (),
          toward: np.ndarray | None = None) -> Branch:
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
    events : sequence of Event, optional
        More events to watch for (snapmem.continuation.events), called after those the options
        and ``until`` ask for.
    toward : (n + 1,) array, optional
        Orient the first tangent along this (x, lambda) direction (branch switching starts a new
        branch this way) instead of by ``options.direction``.

    Returns
    -------
    Branch
    """
    options = resolve_options(options, scene)              # the scene's own defaults where unset
    pb = make_problem(scene, control)
    watch = events_from(options, until, scene) + list(events)
    tracer = Tracer(pb, options, scene)
    x0, lam0 = _start(scene, pb, start)
    F, J = pb.evaluate(x0, lam0)
    if np.max(np.abs(F)) > 1e3 * tracer.tol:
        raise SolverError(f"start state is not an equilibrium (max |R| = {np.max(np.abs(F)):.3e})")
    first = tracer.finish(Point(x0, lam0), J, None if toward is None else Point(x0, lam0, tangent=toward))
    _forget_rounding_inertia(first, pb.stiffness(J))
    points = [first]
    rejections = []
    critical = []
    ds = options.ds
    status, outcome = f"max_steps ({options.max_steps}) reached", Outcome.MAX_STEPS
    for step in range(options.max_steps):
        base = points[-1]
        p, J = tracer.correct(base, ds, abandon_diverging=options.abandon_diverging)
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
            elif (options.stability and base.negative is not None and abs(p.negative - base.negative) >= 2
                  and ds > options.ds_min):
                reason = f"negative eigenvalue count jumped {base.negative} -> {p.negative}: may straddle two critical points"
        if reason is not None:
            rejections.append({"step": step, "s": base.s, "ds": ds, "reason": reason})
            log.info("step %d cut (ds = %.3g): %s", step, ds, reason)
            if ds <= options.ds_min:
                status = f"step too small (ds = {options.ds_min:g}) after: {reason}"
                outcome = Outcome.STEP_TOO_SMALL
                break
            ds = max(0.5 * ds, options.ds_min)
            continue
        inserts, stop = _watch(watch, Step(tracer, base, p, points, []))
        points.extend(sorted(inserts, key=lambda c: c.s))
        critical.extend(c for c in inserts if c.kind in _SPECIAL)
        if stop is not None and stop.at is not None:
            status, outcome = stop.status, stop.outcome
            break
        points.append(p)
        if progress is not None:
            progress(p, {})
        if stop is not None:
            status, outcome = stop.status, stop.outcome
            break
        # adapt the step from the corrector's effort
        factor = (options.target_iterations / max(p.iterations, 1)) ** 0.5
        ds = min(options.ds_max, max(options.ds_min, ds * min(2.0, max(0.5, factor))))
    return _assemble(scene, control, pb, points, critical, rejections, status, outcome, tracer)


def _watch(events: list, step: Step):
    """Call the events on an accepted step: (the points to insert before the new one, the stop
    or None). A stop at a located point ends the calls and drops what was found beyond it, and
    that point is inserted last; else the first stop after the step is returned."""
    stop_after = None
    for event in events:
        found = event.check(step)
        if found is None:
            continue
        step.found.extend(p for p in found.points if p is not None)
        if found.stop is not None and found.stop.at is not None:
            at = found.stop.at
            return [c for c in step.found if c.s < at.s] + [at], found.stop
        if found.stop is not None and stop_after is None:
            stop_after = found.stop
    return step.found, stop_after


def _start(scene, pb: LoadProblem, start):
    """(x, lam) of the first point: ``start`` = (q, loads) if given, else the equilibrium
    reached by loading from rest to the problem's start loads (snapping through folds)."""
    if start is not None:
        q, loads = start
        return pb.unknowns(np.asarray(q, float), scene.resolve_loads(loads))
    loads = pb.start_loads(scene.resolve_loads(None))
    eq = ramp(scene, loads, snap=snap_by_tracing)
    if not eq.converged:
        raise SolverError(f"no start equilibrium at {loads}: {eq.report.reason}")
    return pb.unknowns(eq.q, loads)


def snap_by_tracing(scene: Scene, last: Equilibrium, name: str, value: float) -> Equilibrium | None:
    """Trace past the fold from ``last`` to the next state with load ``name`` = value (the
    snap callback of :func:`snapmem.solvers.ramp.ramp`); None if there is none or it is not
    stable."""
    try:
        branch = trace(scene, name, until={name: value}, start=(last.q, last.loads),
                       options=ContinuationOptions(max_steps=500, stability=True))
    except SnapmemError as exc:
        log.info("snap-through trace failed: %s", exc)
        return None
    except RuntimeError as exc:       # SolverError, or a root finder's "failed to converge" inside the trace
        log.info("snap-through trace failed: %s", exc)
        return None
    end = branch.states[-1]
    if branch.outcome is not Outcome.TARGET_REACHED or end.negative not in (0, None):
        return None
    q = scene.reference_state()
    q[scene.free] = end.x
    loads = {**last.loads, name: value}
    eq = solve(scene, loads, q0=q)
    eq.report.iterations += branch.stats["newton_iterations"]
    return eq if eq.converged else None


#: An eigenvalue within this fraction of the stiffness' largest diagonal entry is rounding: its sign,
#: and so the inertia, says nothing (about 1e5 times the rounding of an LDL^T pivot).
ROUNDING_EIGENVALUE = 1e-8


def _forget_rounding_inertia(first: Point, K) -> None:
    """At a start on a singular state (a slack membrane at rest: no tension, so K has a null
    vector) the eigenvalue nearest zero is rounding, of either sign. Its count is then undetermined
    (``negative`` None: ``negative_eigs`` -1 and ``stable`` empty in the table), and no critical point
    is located between the start and the first step, where the count is exact again."""
    if first.eigs is not None and first.eigs.size and abs(float(first.eigs[0])) <= ROUNDING_EIGENVALUE * scale_of(K):
        first.negative = None


def _assemble(scene, control, pb, points, critical, rejections, status, outcome, tracer) -> Branch:
    """The branch's tables (kinds written as their words) from its points: :class:`Rows`, which
    become DataFrames at their first read (a trace that only writes them imports no pandas)."""
    rows = []
    for p in points:
        m = pb.point_measures(p)
        row = {"s": p.s, "control": p.lam, **m,
               "min_eig": p.test_value if p.eigs is None else float(p.eigs[0]),
               "negative_eigs": -1 if p.negative is None else int(p.negative),
               "stable": bool(p.negative == 0) if p.negative is not None else None,
               "point": _kind_word(p.kind, control) if p.kind in _SPECIAL else "",
               "save_at": p.kind == PointKind.SAVE, "ds": p.ds, "iterations": p.iterations}
        rows.append(row)
    table = Rows(rows)
    crit_rows = []
    for c in critical:
        m = pb.point_measures(c)
        crit_rows.append({"kind": _kind_word(c.kind, control), "s": c.s, "control": c.lam, **m,
                          "min_eig": c.test_value, "located": c.located, "coupling": c.coupling,
                          "crossed": c.crossed, "symmetry_broken": c.symmetry_broken, "mode": c.mode})
    points_table = Rows(crit_rows, columns=None if crit_rows else
                                ["kind", "s", "control", "pressure", "voltage", "E_hat", "volume", "u_max",
                                 "stretch_max", "min_tension", "taut", "breakdown_margin", "rupture_margin", "min_eig", "located", "coupling",
                                 "crossed", "symmetry_broken", "mode"])
    stats = {"steps": int(sum(1 for p in points if p.kind == PointKind.STEP)) - 1, "rejected": len(rejections),
             "newton_iterations": tracer.newton_iterations, "evaluations": tracer.evaluations}
    return Branch(scene, control, table, points_table,
                  Rows(rejections, columns=["step", "s", "ds", "reason"]), status, outcome, points, stats)


def _kind_word(kind: PointKind, control: str) -> str:
    """The word of a point's kind in tables: a limit point under voltage control is the
    electromechanical instability (pull-in), EMI."""
    if kind == PointKind.LP and control == "voltage":
        return PointKind.EMI.value
    return PointKind(kind).value
