"""Layer 5: the equilibrium reached by loading from rest, snapping through folds by continuation.

The load ramp is the solvers' (:func:`snapmem.solvers.ramp.ramp`); where its increments stall at
a limit point, continuation's :func:`~snapmem.continuation.tracer.snap_by_tracing` traces the
branch past the fold. ``snapmem.equilibrium`` is :func:`equilibrium` here (it was
``snapmem.solvers.newton.equilibrium`` before continuation and the solvers were layered apart).
"""

from __future__ import annotations

import dataclasses
from typing import Mapping

from snapmem.continuation.tracer import snap_by_tracing
from snapmem.model.contact import Contact
from snapmem.model.scene import Scene
from snapmem.solvers.newton import Equilibrium, NewtonOptions, finite_or_not_converged, solve
from snapmem.solvers.ramp import LOAD_ORDER, ramp
from snapmem.threads import single_threaded

__all__ = ["LOAD_ORDER", "equilibrium"]


@single_threaded
def equilibrium(scene: Scene, loads: Mapping[str, float] | None = None,
                options: NewtonOptions = NewtonOptions(), min_fraction_step: float = 1e-4) -> Equilibrium:
    """The equilibrium reached by loading quasi-statically from rest to ``loads``.

    Loads are applied one after the other (``LOAD_ORDER``: pressure, then voltage, then any
    other), each in adaptive increments (halved on failure, grown when easy) with a secant
    predictor. If the increments stall, the path has reached a limit point: the membrane snaps.
    The branch is then traced past the fold (pseudo-arclength) to where the load is back at its
    target; the report's reason says so ('snapped through at pressure = ...'). If that state is
    not stable, or the branch never returns to the target, the result is not converged; nor is it
    where the state or an output is NaN or inf (status ``not_finite``).

    With contact, a barrier much thinner than the trace's steps switches on inside one step, and
    the trace past the fold finds no admissible state. Then the barrier width is continued
    instead (:func:`barrier_homotopy`): the equilibrium is found with wider barriers and followed
    as the width shrinks back to the scene's.
    """
    eq = finite_or_not_converged(ramp(scene, loads, options, min_fraction_step, snap=snap_by_tracing))
    if eq.converged or not any(isinstance(t, Contact) for t in scene.terms):
        return eq
    return barrier_homotopy(scene, loads, options, min_fraction_step) or eq


#: Barrier widths tried by :func:`barrier_homotopy`: the scene's times these factors.
WIDENINGS = (10.0, 1e2, 1e3, 1e4)


def with_barrier_width(scene: Scene, factor: float) -> Scene:
    """The same scene with every contact barrier width ``dhat`` multiplied by ``factor``."""
    terms = [dataclasses.replace(t, dhat=t.dhat * factor) if isinstance(t, Contact) else t for t in scene.terms]
    return Scene(scene.meridian, scene.thickness, terms, fixed=scene.fixed, loads=scene.loads, name=scene.name,
                 parameters=scene.parameters, start_guess=scene.start_guess, probes=scene.probes)


def barrier_homotopy(scene: Scene, loads: Mapping[str, float] | None, options: NewtonOptions,
                     min_fraction_step: float, shrink: float = 10.0 ** 0.5) -> Equilibrium | None:
    """The equilibrium of ``scene`` by continuation in the contact barrier width.

    The ramp (with its snap-through trace) is run with barriers ``WIDENINGS`` times wider until
    it converges; that state is followed by Newton solves as the width shrinks by ``shrink`` per
    step (the step halved, in the log of the width, when a solve fails) to the scene's width.
    Each solve starts outside the thinner barrier's reach or inside it with a positive gap, and
    the line search keeps every gap positive, so no step crosses a body.

    Returns
    -------
    Equilibrium or None
        The converged, stable equilibrium of ``scene`` itself (its reason says how the width was
        continued), or None if no widening converged or the continuation stalled.
    """
    for widening in WIDENINGS:
        eq = ramp(with_barrier_width(scene, widening), loads, options, min_fraction_step, snap=snap_by_tracing)
        if eq.converged:
            break
    else:
        return None
    factor, step, solves, iterations = widening, shrink, 0, eq.report.iterations
    while factor > 1.0 and step > 1.0 + 1e-3:
        trial_factor = max(1.0, factor / step)
        trial = solve(with_barrier_width(scene, trial_factor), eq.loads, q0=eq.q, options=options)
        solves += 1
        iterations += trial.report.iterations
        if trial.converged:
            eq, factor = trial, trial_factor
        else:
            step = step ** 0.5
    if factor > 1.0:
        return None
    final = Equilibrium(scene, eq.q, eq.loads, eq.report, eq.stiffness)     # factor 1: the scene's own barrier
    final.report.iterations = iterations
    final.report.reason = (f"{final.report.reason}; barrier width continued from {widening:g} x dhat "
                           f"to dhat in {solves} solves")
    return finite_or_not_converged(final)
