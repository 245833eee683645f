"""Events defined outside the package, passed to trace: what they find, against the exact balloon."""

import numpy as np
import pytest

from snapmem import build_scene, exact
from snapmem.continuation import ContinuationOptions, Event, Found, Outcome, PointKind, Stop, trace
from snapmem.continuation.problems import make_problem

LIMIT = 1.407327e-2          # the model's limit pressure of the balloon at N = 101 (test_continuation)


class VolumeCrossing(Event):
    """Record the points where the enclosed volume crosses ``value`` [m^3]."""

    def __init__(self, value):
        self.value = value

    def check(self, step):
        def f(point):
            return step.output(point, "volume") - self.value

        if f(step.previous) * f(step.new) < 0:
            return Found([step.locate(f, PointKind.SAVE)])
        return None


class StopAtApex(Event):
    """Stop where the largest displacement u_max reaches ``value`` [m]."""

    def __init__(self, value):
        self.value = value

    def check(self, step):
        def f(point):
            return step.output(point, "u_max") - self.value

        if f(step.previous) < 0 <= f(step.new):
            return Found(stop=Stop(Outcome.STOPPED, f"apex at {self.value:g}", step.locate(f, PointKind.END)))
        return None


def test_an_outside_event_records_where_the_volume_crosses_a_value():
    scene = build_scene("balloon", nodes=101)
    stretch = 2.0
    v_rest = scene.volume(scene.reference_state())
    branch = trace(scene, "pressure", until={"stretch": 3.0}, events=[VolumeCrossing(stretch ** 3 * v_rest)])
    saved = branch.table[branch.table["save_at"]]
    assert len(saved) == 1
    row = saved.iloc[0]
    assert row["volume"] == pytest.approx(stretch ** 3 * v_rest, rel=1e-10)       # located on the value
    assert row["stretch"] == pytest.approx(stretch, rel=1e-4)
    assert abs(row["pressure"] - float(exact.balloon_pressure(stretch))) <= 1e-3 * LIMIT
    # the run is otherwise that of the same trace without the event
    plain = trace(scene, "pressure", until={"stretch": 3.0})
    assert branch.status == plain.status and branch.outcome is Outcome.TARGET_REACHED
    assert list(branch.points["pressure"]) == list(plain.points["pressure"])


def test_an_outside_event_stops_the_trace_where_it_says():
    scene = build_scene("balloon", nodes=101)
    branch = trace(scene, "pressure", until={"stretch": 4.0}, events=[StopAtApex(8.0)])
    assert branch.outcome is Outcome.STOPPED and branch.status == "apex at 8"
    assert branch.states[-1].kind == PointKind.END
    last = branch.table.iloc[-1]
    assert last["u_max"] == pytest.approx(8.0, rel=1e-10)
    # held at its base, the uniform sphere (R = 10) moves its apex by 2 R (stretch - 1): stretch 1.4 at u = 8
    assert last["stretch"] == pytest.approx(1.4, rel=1e-3)
    assert abs(last["pressure"] - float(exact.balloon_pressure(last["stretch"]))) <= 1e-3 * LIMIT


def test_point_kinds_and_outcomes_are_todays_words():
    assert [k.value for k in PointKind][:6] == ["", "LP", "BP", "SAVE", "END", "critical"]
    assert {"LE", "LT"} <= {k.value for k in PointKind}
    branch = trace(build_scene("balloon", nodes=31), "pressure", until={"stretch": 4.0},
                   options=ContinuationOptions(stop_at_first_limit=True))
    assert branch.outcome is Outcome.FIRST_LIMIT and branch.status == "stopped at the first limit point"
    assert list(branch.points["kind"]) == ["LP"] and type(branch.points["kind"].iloc[0]) is str
    assert set(branch.table["point"]) == {"", "LP"} and all(type(v) is str for v in branch.table["point"])


def test_a_bracketed_critical_point_of_a_ball_scene_is_classified_on_the_whole_stiffness():
    """Without locating, the null vector comes from inverse iteration on K at the bracket's end:
    with a ball, K has the ball's row and column (a BodyMatrix), which must be kept."""
    from snapmem.catalog.robots import resting
    scene = build_scene("ball_throw", nodes=21)
    q = resting(scene, 500.0)
    options = ContinuationOptions(stop_at_first_limit=True, max_steps=300, locate=False)
    branch = trace(scene, "pressure", start=(q, {"pressure": 500.0}), options=options)
    lp = next(p for p in branch.states if p.kind == PointKind.LP)
    assert not lp.located
    pb = make_problem(scene, "pressure")
    _, K = pb.evaluate(lp.x, lp.lam)
    dense = K.to_dense()
    assert dense.shape == (scene.n_free, scene.n_free)
    w, v = np.linalg.eigh(dense)
    phi = v[:, np.argmin(np.abs(w))]
    Fl = pb.dF_dlam(lp.x, lp.lam)
    coupling = abs(phi @ Fl) / (np.linalg.norm(phi) * np.linalg.norm(Fl))
    assert lp.coupling == pytest.approx(coupling, rel=1e-3)


def test_loss_of_tension_stops_where_the_smallest_tension_reaches_zero():
    from snapmem.continuation import LossOfTension
    scene = build_scene("plate", nodes=31, pressure=0.01, with_loads=("voltage",))
    branch = trace(scene, "voltage", until={"voltage": 3.0}, events=[LossOfTension()])
    t = branch.table
    assert branch.outcome is Outcome.TENSION_LOST
    assert (t["min_tension"].iloc[:-1] > 0).all() and abs(t["min_tension"].iloc[-1]) < 1e-9 * t["min_tension"].max()
    plain = trace(scene, "voltage", until={"voltage": 3.0}).table          # the same branch, on past it
    # a plain trace records the same point (kind LT), between the last taut point and the first slack one, and goes on
    j = int(np.flatnonzero(plain["point"] == "LT")[0])
    assert plain["voltage"].iloc[j] == pytest.approx(t["voltage"].iloc[-1], rel=1e-9)
    assert plain["min_tension"].iloc[j - 1] > 0 >= plain["min_tension"].iloc[j + 1]


def test_a_branch_that_closes_on_itself_ends_where_it_comes_back():
    """The VHB balloon traced in voltage at 300 Pa, 101 nodes, goes past its branch points onto a
    closed loop between two limit points (at 41-81 nodes it runs to loss of ellipticity instead).
    Before ClosedBranch the trace went round it until max_steps (2000 steps, 43 EMI rows of the
    same two folds); now it ends where it meets its first fold again, each fold reported once."""
    scene = build_scene("balloon", nodes=101, with_loads=("voltage",), material="gent", mu=5e4, Jlim=110.0,
                        eps=4.5 * 8.854e-12, R=0.02, H=2e-4, pressure=300.0, voltage=0.0)
    branch = trace(scene, "voltage", until={"stretch_max": 3.0})
    assert branch.outcome is Outcome.CLOSED and branch.outcome.value == "closed"
    folds = branch.points[branch.points["kind"] == "EMI"]
    assert len(folds) == 3 and len(branch.table) < 200
    first_on_loop = folds["voltage"].iloc[1]
    assert branch.status == f"the branch closed on itself: back at its limit point at voltage = {first_on_loop:.6g}"
    assert branch.table["voltage"].iloc[-1] == pytest.approx(first_on_loop, rel=1e-6)
    assert branch.states[-1].kind is PointKind.END


def test_closed_branch_tells_one_limit_point_from_another():
    from snapmem.continuation.branch import Point
    from snapmem.continuation.events import ClosedBranch
    rng = np.random.default_rng(0)
    x = rng.standard_normal(50)
    fold = Point(x=x, lam=2664.342, kind=PointKind.LP)
    assert ClosedBranch.same(fold, Point(x=x * (1 + 1e-8), lam=2664.342 * (1 + 1e-8)))
    assert not ClosedBranch.same(fold, Point(x=x + 3e-2 * np.linalg.norm(x) / 7.0, lam=2664.342))
    assert not ClosedBranch.same(fold, Point(x=x, lam=2750.38))
    assert ClosedBranch.same(Point(x=x, lam=0.0), Point(x=x, lam=0.0))
