"""Newton's method on a scene's residual (equilibria reached by loading from rest: :mod:`snapmem.statics`).

Each iteration is one assembly (gradient and banded K at the trial point) and one band
factorisation and solve. The step is cut (i) to keep free radii positive (fraction to the
boundary), (ii) by halving until the trial state is inside the model's domain (Gent lock,
collapsed edges), and (iii) by halving until the residual norm falls (Armijo on |R|^2, for which
the Newton direction is always a descent direction). The acceptance rules and their constants
are :mod:`snapmem.solvers.rules`, shared with the compiled time step. The assembly at an
accepted trial point is the next iteration's, so an iteration costs one assembly unless a step
is cut.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

from snapmem.errors import check_array, check_int, check_real
from snapmem.model.scene import Evaluation, Scene
from snapmem.solvers import rules
from snapmem.solvers.status import STATUSES, Status  # noqa: F401  (STATUSES: cited here by README and sweeps)


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
    status : Status
        The outcome in one word of :data:`STATUSES` (a str-Enum: it compares, prints and
        serialises as that word), set where the report's ``reason`` is.
    """

    converged: bool
    iterations: int
    residual_norm: float
    reason: str
    step_cuts: int = 0
    history: list = field(default_factory=list)
    status: Status = Status.failed

    def lines(self) -> list[str]:
        return [f"converged: {self.converged}", f"iterations: {self.iterations}",
                f"residual_norm: {self.residual_norm:.3e}", f"step_cuts: {self.step_cuts}",
                f"reason: {self.reason}"]


def newton(residual_and_jacobian: Callable[[np.ndarray], Evaluation], q0: np.ndarray, free: np.ndarray,
           tol: float, options: NewtonOptions = NewtonOptions(),
           inadmissible: Callable[[np.ndarray], str | None] = lambda q: None,
           max_step: Callable[[np.ndarray, np.ndarray], float] = lambda q, dq: 1.0, merit: str = "residual",
           increment_tol: float = 0.0, mass: np.ndarray | None = None):
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
    increment_tol : float
        A time step's increment test [m]: converged also when a full Newton step's
        :func:`snapmem.solvers.rules.increment_error` (over the band positions where ``mass``, one
        per band position, is positive) is at most this. 0 (default): max |R| alone decides.

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
                                     f"left the model's domain: the starting state is outside it ({why})",
                                     status=Status.left_domain)
    ev = residual_and_jacobian(q)
    norm = rules.max_norm(ev.residual)
    last_step = np.inf
    report = NewtonReport(False, 0, norm, "max iterations", status=Status.max_iterations)
    rate, previous = 1.0, np.inf                # the increment test's contraction rate and last full step
    for _ in range(options.max_iterations):
        report.history.append(norm)
        if rules.converged(norm, tol, ev.residual_floor, last_step, q):
            report.converged, report.reason, report.status = True, "converged", Status.converged
            break
        if not math.isfinite(norm):
            report.reason, report.status = "residual is not finite", Status.not_finite
            break
        factors = ev.stiffness.factor()
        if factors.singular:
            report.reason, report.status = "singular tangent stiffness", Status.singular
            break
        dx = factors.solve(-ev.residual)
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
                    if rules.energy_step_accepted(ev_trial.energy, rules.max_norm(ev_trial.residual), ev.energy, norm,
                                                  alpha, slope):
                        break
                elif rules.residual_step_accepted(float(ev_trial.residual @ ev_trial.residual), squared, alpha):
                    break
            alpha *= rules.CUT
            report.step_cuts += 1
        else:
            what = "lowers the energy" if merit == "energy" else "reduces the residual"
            if outside is None:
                report.reason, report.status = f"line search failed: no step {what}", Status.step_too_small
            else:
                report.reason = f"left the model's domain: every trial step was outside it ({outside})"
                report.status = Status.left_domain
            break
        q, ev = trial, ev_trial
        norm = rules.max_norm(ev.residual)
        last_step = rules.step_length(alpha, dx)
        if increment_tol > 0.0:
            if alpha == 1.0:
                increment = rules.moving_increment(dx, mass)
                rate, error = rules.increment_error(increment, previous, rate)
                previous = increment
                if error <= increment_tol:
                    report.history.append(norm)
                    report.converged, report.reason, report.status = True, "converged", Status.converged
                    break
            else:
                previous = np.inf
    report.residual_norm = norm
    if not report.converged and rules.converged_at_end(norm, tol, ev.residual_floor):
        report.converged, report.reason, report.status = True, "converged", Status.converged
    return q, ev, report


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


def finite_or_not_converged(eq: Equilibrium) -> Equilibrium:
    """A converged equilibrium has a finite state and finite outputs: otherwise it is not converged.

    ``eq.report`` becomes ``not_finite`` (converged False) if the state or any of the scene's
    measures at it (volume, u_max, forces, probes) is NaN or inf, its reason naming them; ``eq``
    is returned.
    """
    report = eq.report
    if not report.converged:
        return eq
    bad = [] if np.all(np.isfinite(eq.q)) else ["the state"]
    if not bad:
        bad = [name for name, value in eq.measures().items()
               if isinstance(value, (float, np.floating)) and not math.isfinite(value)]
    if bad:
        report.converged, report.status = False, Status.not_finite
        report.reason = f"the residual is below the tolerance, but {', '.join(bad)} not finite (NaN or inf)"
    return eq


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
    return finite_or_not_converged(Equilibrium(scene, q, loads, report, None if ev is None else ev.stiffness))


def start_guess(scene: Scene, loads: Mapping[str, float]) -> np.ndarray:
    """A starting state for Newton: the scene's own guess if it has one, else the reference."""
    return scene.reference_state() if scene.start_guess is None else scene.start_guess(loads)
