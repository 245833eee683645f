"""Events: what the tracer watches for between two accepted points of a branch.

After every accepted step the tracer calls each event's :meth:`Event.check` with a
:class:`Step` (the previous point, the new one, the branch so far and what the events before
this one found on the step). An event returns ``None`` (nothing here) or a :class:`Found`: points
it located between the two (each with its :class:`~snapmem.continuation.branch.PointKind`), and
optionally a :class:`Stop`. A stop *at* a located point ends the trace there: the points found
beyond it and the new point are dropped and the events after it are not called. A stop without
one ends the trace after the new point; the events after it are still called (one may stop
earlier).

The tracer builds its events from the options and ``until`` (:func:`events_from`), in this
order: :class:`CriticalPoints`, :class:`ClosedBranch`, :class:`LossOfEllipticity`, :class:`LossOfTension` (recording
kind LT, not stopping), :class:`ElectricalBreakdown` and :class:`Rupture` (recording EB and RU,
where the scene sets those limits), :class:`SaveAt`, :class:`Until`, :class:`StopAtFirstLimit`, then
those passed as ``trace(..., events=[...])``. A new event is a subclass of :class:`Event`; no
loop changes. For example, to record where the volume crosses V0::

    class VolumeCrossing(Event):
        def check(self, step):
            f = lambda point: step.output(point, "volume") - V0
            if f(step.previous) * f(step.new) < 0:
                return Found([step.locate(f, PointKind.SAVE)])
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

from snapmem.continuation.branch import Outcome, Point, PointKind
from snapmem.continuation.locate import locate_critical, locate_value, touching
from snapmem.continuation.options import ContinuationOptions
from snapmem.model.local_checks import FailureLimits, LocalState, local_state


@dataclass
class Stop:
    """End the trace.

    Attributes
    ----------
    outcome : Outcome
        Why, in one word (``Branch.outcome``).
    status : str
        Why, in a sentence (``Branch.status``).
    at : Point, optional
        The located point the branch ends at; None to end after the new point.
    """

    outcome: Outcome
    status: str
    at: Point | None = None


@dataclass
class Found:
    """What an event found on a step: located points (in any order) and an optional stop."""

    points: list = field(default_factory=list)
    stop: Stop | None = None


@dataclass
class Step:
    """One accepted step, as events see it.

    Attributes
    ----------
    tracer : snapmem.continuation.tracer.Tracer
        The tracer (its problem ``tracer.pb``, options ``tracer.opt``).
    previous, new : Point
        The accepted points at the two ends of the step.
    points : list of Point
        The branch so far, ending with ``previous`` (accepted and located points).
    found : list of Point
        The points the events called before on this step located.
    """

    tracer: object
    previous: Point
    new: Point
    points: list
    found: list

    def output(self, point: Point, name: str) -> float:
        """The output ``name`` at ``point``: the control ('lam' or its name) or a measure
        (``u_max``, ``stretch_max``, ``volume``, ``min_tension``, the scene's probes, ...)."""
        return self.tracer.pb.output(point, name)

    def locate(self, f: Callable[[Point], float], kind: PointKind, needs_eigenvalues: bool = False) -> Point | None:
        """The point between ``previous`` and ``new`` where f(point) = 0 (f must change sign
        there), of ``kind``; None if it could not be located (the failure is logged).
        ``needs_eigenvalues``: compute the stability of every point on the way."""
        return locate_value(self.tracer, self.previous, self.new, lambda point, s: f(point), kind,
                            needs_eigenvalues=needs_eigenvalues)


class Event:
    """Base of the events a trace watches for: override :meth:`check`."""

    def check(self, step: Step) -> Found | None:
        """What this event finds on ``step``: None, or the points located and/or a stop."""
        raise NotImplementedError


class CriticalPoints(Event):
    """Limit and bifurcation points: where the negative eigenvalue count changes between the two
    points, or an eigenvalue dips to zero and back (then three points are compared)."""

    def check(self, step: Step) -> Found | None:
        previous, new = step.previous, step.new
        if previous.negative is None:          # a start whose inertia rounding leaves undetermined
            return None
        if new.negative != previous.negative:
            return Found([locate_critical(step.tracer, previous, new)])
        if len(step.points) >= 2:
            return Found(touching(step.tracer, step.points[-2], previous, new))
        return None


class ClosedBranch(Event):
    """Stop where the branch comes back to a limit point it has passed: it is closed (an isola, or
    a loop the trace entered at a branch point), and the trace would go round it until
    ``max_steps``, reporting its limit points again each time. The point located there ends the
    branch (kind END, outcome CLOSED), so that every critical point of the loop is reported once.
    Watching the limit points is enough: a closed branch has at least two, where the control
    reaches its extremes along it. Two limit points are the same when their control values and
    states agree to TOLERANCE, relative (a loop's limit point located again differs by 1e-8 in
    the cases seen; two different ones by far more)."""

    TOLERANCE = 1e-5

    def check(self, step: Step) -> Found | None:
        for point in step.found:
            if point.kind != PointKind.LP:
                continue
            earlier = next((p for p in step.points if p.kind == PointKind.LP and self.same(p, point)), None)
            if earlier is not None:
                point.kind = PointKind.END
                control = step.tracer.pb.control
                return Found(stop=Stop(Outcome.CLOSED, f"the branch closed on itself: back at its limit point at "
                                                       f"{control} = {earlier.lam:.6g}", point))
        return None

    @classmethod
    def same(cls, a: Point, b: Point) -> bool:
        """Whether two points are one: control and state within TOLERANCE of each other, relative."""
        tol = cls.TOLERANCE
        scale = max(float(np.linalg.norm(a.x)), float(np.linalg.norm(b.x)), np.finfo(float).tiny)
        return (abs(a.lam - b.lam) <= tol * max(abs(a.lam), abs(b.lam), np.finfo(float).tiny)
                and float(np.linalg.norm(a.x - b.x)) <= tol * scale)


class SaveAt(Event):
    """Points located exactly where the control parameter crosses any of ``values``."""

    def __init__(self, values):
        self.values = sorted(values)

    def check(self, step: Step) -> Found | None:
        previous, new = step.previous, step.new
        located = []
        for value in self.values:
            if (previous.lam - value) * (new.lam - value) < 0:
                point = locate_value(step.tracer, previous, new, lambda pt, s, v=value: pt.lam - v, PointKind.SAVE,
                                     needs_eigenvalues=False)
                if point is not None:
                    located.append(point)
        return Found(located) if located else None


class Until(Event):
    """Stop where an output reaches its value: ``targets`` maps output names (as
    :meth:`Step.output` takes them) to values; the first one reached on a step ends the branch at
    the point located on it (kind END)."""

    def __init__(self, targets: Mapping[str, float]):
        self.targets = dict(targets)

    def check(self, step: Step) -> Found | None:
        previous, new = step.previous, step.new
        for name, value in self.targets.items():
            f0 = step.output(previous, name) - value
            f1 = step.output(new, name) - value
            if f0 * f1 <= 0 and f1 != f0:
                point = locate_value(step.tracer, previous, new, lambda pt, s, n=name, v=value: step.output(pt, n) - v,
                                     PointKind.END, needs_eigenvalues=False)
                if point is None:          # not located: go on past it
                    return None
                return Found(stop=Stop(Outcome.TARGET_REACHED, f"{name} reached {value:g}", point))
        return None


class StopAtFirstLimit(Event):
    """Stop after the step on which an event before this one located a limit point."""

    def check(self, step: Step) -> Found | None:
        if any(point.kind == PointKind.LP for point in step.found):
            return Found(stop=Stop(Outcome.FIRST_LIMIT, "stopped at the first limit point"))
        return None


class LossOfTension(Event):
    """Where the membrane goes slack: the smallest principal tension ``min_tension`` [N/m] falls
    to zero between two points.

    With ``stop`` (the default) the branch ends at the point located there (kind END, outcome
    TENSION_LOST). Without, the point is recorded (kind LT: the membrane wrinkles there and the
    model's answer beyond is not physical) and the trace goes on; the tracer watches for this
    at every step (:func:`events_from`).
    """

    def __init__(self, stop: bool = True):
        self.stop = stop

    def check(self, step: Step) -> Found | None:
        def tension(point):
            return step.output(point, "min_tension")

        if not tension(step.previous) > 0.0 >= tension(step.new):
            return None
        if not self.stop:
            point = step.locate(tension, PointKind.LT)
            return None if point is None else Found([point])
        # the recording event the tracer runs first has located it already: end there
        point = next((p for p in step.found if p.kind == PointKind.LT), None) or step.locate(tension, PointKind.END)
        if point is None:
            return None
        point.kind = PointKind.END
        control = step.tracer.pb.control
        return Found(stop=Stop(Outcome.TENSION_LOST, f"tension lost at {control} = {point.lam:.6g}", point))


class LossOfEllipticity(Event):
    """Stop where the membrane energy (electric term included) stops being strongly elliptic on
    some edge (:func:`snapmem.model.local_checks.ellipticity_margins`): beyond it the model is
    ill-posed (mesh-scale modes, critical points that depend on the mesh), so the branch ends at
    the point located there (kind LE, outcome ELLIPTICITY_LOST) and nothing past it is reported.
    The tracer watches for this at every step (:func:`events_from`); scenes without a membrane
    energy are not checked.
    """

    def __init__(self):
        self._cache: dict = {}           # id(point) -> (point, LocalState), the last few points

    def local(self, step: Step, point: Point) -> LocalState | None:
        """The local checks at ``point`` (cached: each accepted point is checked once)."""
        hit = self._cache.get(id(point))
        if hit is not None and hit[0] is point:
            return hit[1]
        q, loads = step.tracer.pb.state(point.x, point.lam)
        state = local_state(step.tracer.scene, q, loads, with_tension=False)     # tension: LossOfTension
        if len(self._cache) > 8:
            self._cache.clear()
        self._cache[id(point)] = (point, state)
        return state

    def check(self, step: Step) -> Found | None:
        before, after = self.local(step, step.previous), self.local(step, step.new)
        if before is None or not before.ellipticity > 0.0 >= after.ellipticity:
            return None
        at = step.locate(lambda point: self.local(step, point).ellipticity, PointKind.LE)
        if at is None:             # not located: end at the new point, the first one past it
            at = step.new
            at.kind, at.located = PointKind.LE, False
        state = self.local(step, at)
        control = step.tracer.pb.control
        status = (f"loss of ellipticity at {control} = {at.lam:.6g}, stretch {state.stretch:.4g}: "
                  "the membrane model is ill-posed beyond this point")
        return Found(stop=Stop(Outcome.ELLIPTICITY_LOST, status, at))


class FailureMargin(Event):
    """Where a failure margin (an output that fails at 1: :func:`snapmem.model.local_checks.failure_margins`)
    falls to 1 between two points: the point there is recorded (of ``kind``) and the trace goes
    on, so that what lies beyond the failure stays visible (the window of a design)."""

    measure: str = ""
    kind: PointKind = PointKind.SAVE

    def check(self, step: Step) -> Found | None:
        def excess(point):
            return step.output(point, self.measure) - 1.0

        if not excess(step.previous) > 0.0 >= excess(step.new):
            return None
        point = step.locate(excess, self.kind)
        return None if point is None else Found([point])


class ElectricalBreakdown(FailureMargin):
    """EB: the true field reaches the breakdown strength on some edge (``breakdown_margin`` = 1)."""

    measure, kind = "breakdown_margin", PointKind.EB


class Rupture(FailureMargin):
    """RU: the largest total stretch reaches the scene's ``stretch_limit`` (``rupture_margin`` = 1)."""

    measure, kind = "rupture_margin", PointKind.RU


def events_from(options: ContinuationOptions, until: Mapping[str, float] | None = None, scene=None) -> list[Event]:
    """The events ``options`` and ``until`` ask for, in the order the tracer calls them (with
    ``scene``, the failure events of the limits it sets: :class:`ElectricalBreakdown`,
    :class:`Rupture`)."""
    events: list[Event] = []
    if options.stability:
        events += [CriticalPoints(), ClosedBranch()]
    events += [LossOfEllipticity(), LossOfTension(stop=False)]
    limits = FailureLimits() if scene is None else FailureLimits.of(scene)
    if limits.E_breakdown is not None:
        events.append(ElectricalBreakdown())
    if limits.stretch_limit is not None:
        events.append(Rupture())
    if options.save_at:
        events.append(SaveAt(options.save_at))
    if until:
        events.append(Until(until))
    if options.stop_at_first_limit:
        events.append(StopAtFirstLimit())
    return events
