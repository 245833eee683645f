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
import math
from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

from snapmem.errors import check_array, check_int, check_real
from snapmem.model.scene import Evaluation, Scene

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


#: How a solve can end: NewtonReport.status is one of these words (``reason`` says more).
STATUSES = {
    "converged": "max |R| on the free degrees of freedom is below the tolerance",
    "max_iterations": "the iteration limit was reached before convergence",
    "step_too_small": "no step along the Newton direction reduces the residual (line search failed)",
    "left_domain": "every trial step, however short, left the model's domain (material lock, "
                   "non-positive radius, collapsed edge)",
    "singular": "the tangent stiffness is singular",
    "not_finite": "the residual is NaN or inf",
    "no_equilibrium": "loading from rest cannot reach the load: a limit point or the end of the "
                      "material's domain lies before it",
    "failed": "any other failure (see reason)",
}
_REASON_STATUS = (("converged", "converged"), ("max iterations", "max_iterations"),
                  ("line search failed", "step_too_small"), ("left the model's domain", "left_domain"),
                  ("singular", "singular"), ("residual is not finite", "not_finite"),
                  ("no equilibrium", "no_equilibrium"))


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
        ``status`` is the same as one word of :data:`STATUSES`.
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

    @property
    def status(self) -> str:
        """One word of :data:`STATUSES` for this report's ``reason``."""
        if self.converged:
            return "converged"
        for start, status in _REASON_STATUS:
            if self.reason.startswith(start):
                return status
        return "failed"

    def lines(self) -> list[str]:
        return [f"converged: {self.converged}", f"iterations: {self.iterations}",
                f"residual_norm: {self.residual_norm:.3e}", f"step_cuts: {self.step_cuts}",
                f"reason: {self.reason}"]


def newton(residual_and_jacobian: Callable[[np.ndarray], Evaluation], q0: np.ndarray, free: np.ndarray,
           tol: float, options: NewtonOptions = NewtonOptions(),
           inadmissible: Callable[[np.ndarray], str | None] = lambda q: None,
           max_step: Callable[[np.ndarray, np.ndarray], float] = lambda q, dq: 1.0, merit: str = "residual"):
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
    merit : {'residual', 'energy'}
        When a step is accepted: 'residual', Armijo on |R|^2 (for any equilibrium, stable or
        not); 'energy', for a minimisation (a time step's incremental potential): when it lowers
        the energy by the Armijo fraction of its slope, or halves max |R| (far fewer cuts: full
        Newton steps in strongly nonlinear states often raise |R|^2 while lowering the energy).

    Returns
    -------
    q : ndarray
        Last accepted state (the start if nothing was accepted).
    evaluation : Evaluation or None
        Assembly at q (None if the start is outside the model's domain).
    report : NewtonReport
    """
    q = np.array(q0, dtype=float)
    why = inadmissible(q)
    if why is not None:
        return q, None, NewtonReport(False, 0, float("nan"),
                                     f"left the model's domain: the starting state is outside it ({why})")
    ev = residual_and_jacobian(q)
    norm = _norm(ev.residual)
    last_step = np.inf
    report = NewtonReport(False, 0, norm, "max iterations")
    for _ in range(options.max_iterations):
        report.history.append(norm)
        floor_tol = max(tol, ev.residual_floor)
        if norm <= floor_tol or (norm <= 1e3 * floor_tol and last_step <= 1e-10 * np.abs(q).max()):
            # converged; or the last Newton step was at the rounding of q and the residual is within
            # 1e3 of the tolerance: the rounding floor of a stiff state (a law near its lock). A
            # slowly converging singular problem takes steps far larger than that.
            report.converged, report.reason = True, "converged"
            break
        if not math.isfinite(norm):
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
        squared = float(ev.residual @ ev.residual)
        slope = float(ev.residual @ dx) if merit == "energy" else 0.0
        report.iterations += 1
        outside = None
        for _cut in range(options.max_cuts + 1):
            trial = q + alpha * dq
            outside = inadmissible(trial)
            if outside is None:
                ev_trial = residual_and_jacobian(trial)
                if merit == "energy":
                    trial_norm = _norm(ev_trial.residual)
                    if np.isfinite(ev_trial.energy) and np.isfinite(trial_norm) and (
                            ev_trial.energy <= ev.energy + 1e-4 * alpha * min(slope, 0.0) or trial_norm <= 0.5 * norm):
                        break
                else:
                    trial_squared = float(ev_trial.residual @ ev_trial.residual)
                    if math.isfinite(trial_squared) and trial_squared <= (1.0 - 1e-4 * alpha) * squared:
                        break
            alpha *= 0.5
            report.step_cuts += 1
        else:
            what = "lowers the energy" if merit == "energy" else "reduces the residual"
            report.reason = (f"line search failed: no step {what}" if outside is None else
                             f"left the model's domain: every trial step was outside it ({outside})")
            break
        q, ev = trial, ev_trial
        norm = _norm(ev.residual)
        last_step = alpha * float(np.abs(dx).max()) if dx.size else 0.0
    report.residual_norm = norm
    if not report.converged and norm <= max(tol, ev.residual_floor):
        report.converged, report.reason = True, "converged"
    return q, ev, report


def _norm(r: np.ndarray) -> float:
    return float(np.abs(r).max()) if r.size else 0.0


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
    else:
        q0 = check_array("q0", q0, scene.reference_state().shape)
    q, ev, report = newton(lambda x: scene.evaluate(x, loads, order=2), q0, scene.free,
                           options.tol * scene.force_scale, options, scene.inadmissible, scene.max_step)
    return Equilibrium(scene, q, loads, report, None if ev is None else ev.stiffness)


def start_guess(scene: Scene, loads: Mapping[str, float]) -> np.ndarray:
    """A starting state for Newton: the scene's own guess if it has one, else the reference."""
    return scene.reference_state() if scene.start_guess is None else scene.start_guess(loads)
