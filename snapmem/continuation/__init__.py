"""Layer 4: pseudo-arclength continuation of equilibrium branches, their critical points and fold curves.

Modules: ``options`` (ContinuationOptions, FoldOptions, CONTROLS), ``branch`` (Point, Branch,
PointKind, Outcome, load_points), ``problems`` (what is continued), ``tracer`` (the
predictor-corrector loop, :func:`trace`), ``events`` (what the loop watches for), ``locate``
(locating and classifying points between two steps), ``folds`` (:func:`fold_curve`),
``switching`` (:func:`switch_branch`), ``diagram`` (:class:`Diagram`), ``modes`` and ``hysteresis``.
"""

from snapmem.continuation.branch import Branch, Outcome, Point, PointKind, load_points
from snapmem.continuation.events import (ClosedBranch, CriticalPoints, Event, Found, LossOfTension, SaveAt, Step, Stop,
                                         StopAtFirstLimit, Until, events_from)
from snapmem.continuation.folds import fold_curve
from snapmem.continuation.options import CONTROLS, ContinuationOptions, FoldOptions
from snapmem.continuation.problems import LoadProblem, VolumeProblem, make_problem
from snapmem.continuation.tracer import Tracer, snap_by_tracing, trace
from snapmem.continuation.diagram import Connection, Diagram, read_diagram
from snapmem.continuation.switching import bifurcation_direction, switch_branch
import snapmem.continuation.chambers  # noqa: F401  (registers the multi-membrane problems)

__all__ = [
    "CONTROLS", "ContinuationOptions", "FoldOptions",
    "Point", "PointKind", "Branch", "Outcome", "load_points",
    "LoadProblem", "VolumeProblem", "make_problem",
    "Tracer", "trace", "snap_by_tracing",
    "Event", "Step", "Found", "Stop", "CriticalPoints", "ClosedBranch", "SaveAt", "Until", "StopAtFirstLimit",
    "LossOfTension",
    "events_from",
    "fold_curve",
    "Diagram", "Connection", "read_diagram", "switch_branch", "bifurcation_direction",
]
