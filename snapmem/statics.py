"""Layer 5: the equilibrium reached by loading from rest, snapping through folds by continuation.

The load ramp is the solvers' (:func:`snapmem.solvers.ramp.ramp`); where its increments stall at
a limit point, continuation's :func:`~snapmem.continuation.tracer.snap_by_tracing` traces the
branch past the fold. ``snapmem.equilibrium`` is :func:`equilibrium` here (it was
``snapmem.solvers.newton.equilibrium`` before continuation and the solvers were layered apart).
"""

from __future__ import annotations

from typing import Mapping

from snapmem.continuation.tracer import snap_by_tracing
from snapmem.model.scene import Scene
from snapmem.solvers.newton import Equilibrium, NewtonOptions, finite_or_not_converged
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
    """
    return finite_or_not_converged(ramp(scene, loads, options, min_fraction_step, snap=snap_by_tracing))
