"""Newton's method on a scene's residual, and equilibria reached by loading from rest.

Each iteration is one assembly (gradient and banded K at the trial point) and one band LU
solve. The step is cut (i) to keep free radii positive (fraction to the boundary), (ii) by
halving until the trial state is inside the model's domain (Gent lock, collapsed edges), and
(iii) by halving until the residual norm falls (Armijo on |R|^2, for which the Newton
direction is always a descent direction). The assembly at an accepted trial point is the next
iteration's, so an iteration costs one assembly unless a step is cut.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

from .errors import SolverError, check_int, check_real
from .scene import Evaluation, Scene

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class NewtonOptions:
    """Tolerances and limits of the Newton solver.

    Attributes
    ----------
    tol : float
        Converged when max |R| <= tol * scene.force_scale (default 1e-10).
    max_iterations : int
        Default 30.
    max_cuts : int
        Step halvings allowed in one iteration (default 30).
    """

    tol: float = 1e-10
    max_iterations: int = 30
    max_cuts: int = 30

    def __post_init__(self):
        check_real("tol", self.tol, minimum=0.0, min_inclusive=False)
        check_int("max_iterations", self.max_iterations, minimum=1)
        check_int("max_cuts", self.max_cuts, minimum=0)


@dataclass
class NewtonReport:
    """How a Newton solve went.

    Attributes
    ----------
    converged : bool
    iterations : int
        Newton iterations (linear solves) taken.
    residual_norm : float
        max |R| over free degrees of freedom at the returned state [N].
    reason : str
        'converged', or why not ('max iterations', 'singular tangent', 'line search failed: ...').
    step_cuts : int
        Total step halvings.
    history : list of float
        Residual norm before each iteration.
    """

    converged: bool
    iterations: int
    residual_norm: float
    reason: str
    step_cuts: int = 0
    history: list = field(default_factory=list)

    def lines(self) -> list[str]:
        return [f"converged: {self.converged}", f"iterations: {self.iterations}",
                f"residual_norm: {self.residual_norm:.3e}", f"step_cuts: {self.step_cuts}",
                f"reason: {self.reason}"]


def newton(residual_and_jacobian: Callable[[np.ndarray], Evaluation], q0: np.ndarray, free: np.ndarray,
           tol: float, options: NewtonOptions = NewtonOptions(),
           inadmissible: Callable[[np.ndarray], str | None] = lambda q: None,
           max_step: Callable[[np.ndarray, np.ndarray], float] = lambda q, dq: 1.0):
    """Solve R(q) = 0 on the free degrees of freedom by damped Newton.

    Parameters
    ----------
    residual_and_jacobian : callable
        q -> Evaluation with ``residual`` (n_free,) and ``stiffness`` (BandedMatrix).
    q0 : ndarray (n_dof,)
        Starting state; fixed entries keep their values.
    free : ndarray of int
        Free degree of freedom for each band position.
    tol : float
        Absolute tolerance on max |R|.

    Returns
    -------
    q : ndarray
        Last accepted state (the start if nothing was accepted).
    evaluation : Evaluation
        Assembly at q.
    report : NewtonReport
    """
    q = np.array(q0, dtype=float)
    why = inadmissible(q)
    if why is not None:
        raise SolverError(f"starting state is outside the model's domain: {why}")
    ev = residual_and_jacobian(q)
    norm = _norm(ev.residual)
    report = NewtonReport(False, 0, norm, "max iterations")
    for _ in range(options.max_iterations):
        report.history.append(norm)
        if norm <= tol:
            report.converged, report.reason = True, "converged"
            break
        if not np.isfinite(norm):
            report.reason = "residual is not finite"
            break
        lu = ev.stiffness.lu()
        if lu.singular:
            report.reason = "singular tangent stiffness"
            break
        dx = lu.solve(-ev.residual)
        dq = np.zeros_like(q)
        dq[free] = dx
        alpha = min(1.0, max_step(q, dq))
        merit = float(ev.residual @ ev.residual)
        report.iterations += 1
        for _cut in range(options.max_cuts + 1):
            trial = q + alpha * dq
            if inadmissible(trial) is None:
                ev_trial = residual_and_jacobian(trial)
                trial_merit = float(ev_trial.residual @ ev_trial.residual)
                if np.isfinite(trial_merit) and trial_merit <= (1.0 - 1e-4 * alpha) * merit:
                    break
            alpha *= 0.5
            report.step_cuts += 1
        else:
            report.reason = "line search failed: no step reduces the residual"
            break
        q, ev = trial, ev_trial
        norm = _norm(ev.residual)
    report.residual_norm = norm
    if not report.converged and norm <= tol:
        report.converged, report.reason = True, "converged"
    return q, ev, report


def _norm(r: np.ndarray) -> float:
    return float(np.max(np.abs(r))) if r.size else 0.0


@dataclass
class Equilibrium:
    """An equilibrium state of a scene with its loads, solver report and scalar measures."""

    scene: Scene
    q: np.ndarray
    loads: dict
    report: NewtonReport
    stiffness: object = None

    @property
    def converged(self) -> bool:
        return self.report.converged

    def measures(self) -> dict:
        return self.scene.measures(self.q, self.loads)


def solve(scene: Scene, loads: Mapping[str, float] | None = None, q0: np.ndarray | None = None,
          options: NewtonOptions = NewtonOptions()) -> Equilibrium:
    """Newton solve of the scene's equilibrium at ``loads`` from ``q0`` (default: its start guess)."""
    loads = scene.resolve_loads(loads)
    if q0 is None:
        q0 = start_guess(scene, loads)
    q, ev, report = newton(lambda x: scene.evaluate(x, loads, order=2), q0, scene.free,
                           options.tol * scene.force_scale, options, scene.inadmissible, scene.max_step)
    return Equilibrium(scene, q, loads, report, ev.stiffness)


def start_guess(scene: Scene, loads: Mapping[str, float]) -> np.ndarray:
    """A starting state for Newton: the scene's own guess if it has one, else the reference."""
    return scene.reference_state() if scene.start_guess is None else scene.start_guess(loads)


def equilibrium(scene: Scene, loads: Mapping[str, float] | None = None,
                options: NewtonOptions = NewtonOptions(), min_fraction_step: float = 1e-6) -> Equilibrium:
    """The equilibrium reached by loading quasi-statically from rest to ``loads``.

    Tries Newton at the full load first; if that fails, scales all loads by t from 0 to 1 in
    adaptive increments (halved on failure, grown on easy steps) with a secant predictor. If
    the increments fall below ``min_fraction_step`` the load path has passed a limit point
    (or the model's domain ends) and the last converged state is returned, not converged.
    """
    target = scene.resolve_loads(loads)
    base = {k: 0.0 for k in target}

    def at(t):
        return {k: base[k] + t * (target[k] - base[k]) for k in target}

    first = solve(scene, target, options=options)
    if first.converged and _is_stable(first):
        return first
    t, dt = 0.0, 0.25
    if scene.start_guess is not None:       # singular at rest (a flat plate): start just above
        t = 1e-3
    q = start_guess(scene, at(t))
    previous = None
    last = solve(scene, at(t), q0=q, options=options)
    if not last.converged:
        return last
    iterations = last.report.iterations
    while t < 1.0:
        t_new = min(1.0, t + dt)
        guess = last.q if previous is None else last.q + (last.q - previous[1]) * (t_new - t) / (t - previous[0])
        trial = solve(scene, at(t_new), q0=guess, options=options)
        iterations += trial.report.iterations
        if trial.converged:
            previous, last, t = (t, last.q), trial, t_new
            if trial.report.iterations <= 4:
                dt *= 1.5
        else:
            dt *= 0.5
            if dt < min_fraction_step:
                loads_reached = ", ".join(f"{k}={v:.6g}" for k, v in at(t).items())
                last.report.converged = False
                last.report.reason = (f"no equilibrium on the load path from rest beyond {loads_reached} "
                                      "(a limit point or the edge of the material's domain)")
                return last
    last.report.iterations = iterations
    return last


def _is_stable(eq: Equilibrium) -> bool:
    return eq.stiffness is not None and eq.stiffness.smallest_eigenvalues(1)[0] > 0
