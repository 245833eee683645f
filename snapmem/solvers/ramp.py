"""Equilibria reached by loading quasi-statically from rest: Newton on adaptive load increments.

Loads are applied one after the other (:data:`LOAD_ORDER`: pressure, then voltage, then any
other), each in adaptive increments (halved on failure, grown when easy) with a secant
predictor. If the increments stall, the path has reached a limit point (or the end of the
material's domain). What happens then is the caller's: a ``snap`` callback may carry the state
past the fold (snapmem.statics.equilibrium passes continuation's, which traces the branch to
where the load is back at its target); without one, or if it finds nothing, the result is not
converged.
"""

from __future__ import annotations

from typing import Callable, Mapping

from snapmem.model.scene import Scene
from snapmem.solvers.newton import Equilibrium, NewtonOptions, solve, start_guess
from snapmem.solvers.status import Status
from snapmem.threads import single_threaded

#: The order in which :func:`ramp` applies loads (the paper inflates, then actuates).
LOAD_ORDER = ("pressure", "voltage")

#: snap(scene, last, name, value): the equilibrium past the fold where load ``name`` = value,
#: from ``last``, the last equilibrium the increments reached; or None if there is none.
Snap = Callable[[Scene, Equilibrium, str, float], "Equilibrium | None"]


@single_threaded
def ramp(scene: Scene, loads: Mapping[str, float] | None = None, options: NewtonOptions = NewtonOptions(),
         min_fraction_step: float = 1e-4, snap: Snap | None = None) -> Equilibrium:
    """The equilibrium reached by loading from rest to ``loads`` in adaptive increments.

    Parameters
    ----------
    scene : Scene
    loads : mapping, optional
        The target loads (default: the scene's own).
    options : NewtonOptions
        Of every increment's Newton solve.
    min_fraction_step : float
        The smallest increment, as a fraction of one load's change, before the path counts as
        stalled (default 1e-4).
    snap : callable, optional
        Called where the increments stall (see :data:`Snap`); its result's report says so
        ('snapped through at pressure = ...'). None: a stall ends the ramp unconverged.

    Returns
    -------
    Equilibrium
        Its report counts the Newton iterations of the whole path.
    """
    target = scene.resolve_loads(loads)
    current = {k: 0.0 for k in target}
    order = [k for k in LOAD_ORDER if k in target] + [k for k in target if k not in LOAD_ORDER]
    if scene.start_guess is not None and any(target.values()):
        # singular at rest (a flat plate): start just off rest, on the way to the target
        current = {k: 1e-3 * v for k, v in target.items()}
    last = solve(scene, current, q0=start_guess(scene, current), options=options)
    if not last.converged:
        last.report.reason = f"no equilibrium at the start of the load path: {last.report.reason}"
        last.report.status = Status.no_equilibrium
        return last
    iterations, notes = last.report.iterations, []
    for name in order:
        if target[name] == current[name]:
            continue
        last, its, note = _ramp_load(scene, last, current, name, target[name], options, min_fraction_step, snap)
        iterations += its
        current = dict(last.loads)
        if note:
            notes.append(note)
        if not last.converged:
            break
    last.report.iterations = iterations
    if last.converged and notes:
        last.report.reason = "converged; " + "; ".join(notes)
    return last


def _ramp_load(scene, start: Equilibrium, loads, name, value, options, min_fraction_step, snap):
    """Take load ``name`` from loads[name] to ``value`` by increments; ``snap`` through folds.
    Returns (equilibrium, Newton iterations, note or None)."""
    a = loads[name]

    def at(t):
        return {**loads, name: a + t * (value - a)}

    t, dt, last, previous, iterations = 0.0, 0.25, start, None, 0
    while t < 1.0:
        t_new = min(1.0, t + dt)
        guess = last.q if previous is None else last.q + (last.q - previous[1]) * (t_new - t) / (t - previous[0])
        if scene.inadmissible(guess) is not None:      # the secant overshot a lock: restart from the last state
            guess = last.q
        trial = solve(scene, at(t_new), q0=guess, options=options)
        iterations += trial.report.iterations
        if trial.converged:
            previous, last, t = (t, last.q), trial, t_new
            if trial.report.iterations <= 4:
                dt *= 1.5
            continue
        dt *= 0.5
        if dt < min_fraction_step:
            snapped = None if snap is None else snap(scene, last, name, value)
            if snapped is None:
                last.report.converged, last.report.status = False, Status.no_equilibrium
                last.report.reason = (f"no equilibrium on the load path beyond {name} = {at(t)[name]:.6g} "
                                      "(a limit point or the edge of the material's domain)")
                return last, iterations, None
            return snapped, iterations + snapped.report.iterations, f"snapped through at {name} = {at(t)[name]:.6g}"
    return last, iterations, None
