"""A table of bad inputs: each gives its own clear message (naming the parameter, the value and what
is allowed) through the Python API and through the command line, and never a traceback.

Two kinds of row: bad input raises SnapmemError (the CLI prints one line and exits 2); input that
is valid but has no answer (a voltage beyond any equilibrium, a start past the Gent lock) comes back
as a result whose status says so (the CLI prints the report and exits 1).
"""

import subprocess
import sys

import numpy as np
import pytest

from snapmem import Meridian, NewtonOptions, SnapmemError, build_scene, equilibrium, solve
from snapmem.cli import main, parse_sets
from snapmem.model.materials import Gent, MooneyRivlin
from snapmem.continuation import load_points
from snapmem.dynamics.driver import Trajectory
from snapmem.model.scene import Scene
from snapmem.sweeps.sweep import make_job, parse_axis, sweep

NAN, INF = float("nan"), float("inf")


def eq(scene, **params):
    return lambda: build_scene(scene, **params)


def solve_with(**kw):
    return lambda: solve(build_scene("balloon", nodes=11), **kw)


def write_files():
    """Broken files in the current folder: truncated, not a zip, empty, pickled objects, foreign."""
    np.savez_compressed("good.npz", x=np.ones(50))
    data = open("good.npz", "rb").read()
    open("truncated.npz", "wb").write(data[: len(data) // 2])
    open("text.npz", "w").write("hello\n")
    open("empty.npz", "wb").close()
    np.savez("objects.npz", x=np.array([{"a": 1}], dtype=object))


def load(reader, name):
    def call():
        write_files()
        return reader(name)
    return call


def past_gent_lock():
    """A start 3x the reference: I1 - 3 = 15 > Jlim = 1."""
    scene = build_scene("balloon", nodes=11, material="gent", Jlim=1.0)
    return solve(scene, {"pressure": 0.01}, q0=scene.reference_state() * 3.0)


# (id, API call, CLI argv or None, words the message must contain)
ERRORS = [
    ("H zero", eq("balloon", H=0), ["equilibrium", "balloon", "--set", "H=0"], ["H = 0", "must be > 0"]),
    ("H negative", eq("balloon", H=-0.1), ["equilibrium", "balloon", "--set", "H=-0.1"], ["H = -0.1", "must be > 0"]),
    ("R nan", eq("balloon", R=NAN), ["equilibrium", "balloon", "--set", "R=nan"], ["R = nan", "must be finite"]),
    ("R inf", eq("balloon", R=INF), ["equilibrium", "balloon", "--set", "R=inf"], ["R = inf", "must be finite"]),
    ("R -inf", eq("plate", R=-INF), ["equilibrium", "plate", "--set", "R=-inf"], ["R = -inf", "must be finite"]),
    ("R string", eq("balloon", R="ten"), ["equilibrium", "balloon", "--set", "R=ten"], ["R = 'ten'", "must be a number"]),
    ("R zero", eq("plate", R=0), ["equilibrium", "plate", "--set", "R=0"], ["R = 0", "must be > 0"]),
    ("nodes 2", eq("plate", nodes=2), ["equilibrium", "plate", "--set", "nodes=2"], ["nodes = 2", ">= 3"]),
    ("nodes 0", eq("balloon", nodes=0), ["equilibrium", "balloon", "--set", "nodes=0"], ["nodes = 0", ">= 3"]),
    ("nodes negative", eq("torus", nodes=-5), ["equilibrium", "torus", "--set", "nodes=-5"], ["nodes = -5", ">= 3"]),
    ("nodes fraction", eq("balloon", nodes=10.5), ["equilibrium", "balloon", "--set", "nodes=10.5"],
     ["nodes = 10.5", "must be an integer"]),
    ("nodes string", eq("balloon", nodes="many"), ["equilibrium", "balloon", "--set", "nodes=many"],
     ["nodes = 'many'", "must be a number"]),
    ("c1 zero", eq("balloon", c1=0), ["equilibrium", "balloon", "--set", "c1=0"], ["c1 = 0", "must be > 0"]),
    ("c1 negative", eq("balloon", c1=-0.4), ["equilibrium", "balloon", "--set", "c1=-0.4"], ["c1 = -0.4", "must be > 0"]),
    ("c2 negative", eq("balloon", c2=-0.1), ["equilibrium", "balloon", "--set", "c2=-0.1"], ["c2 = -0.1", ">= 0"]),
    ("Jlim zero", eq("plate", material="gent", Jlim=0), ["equilibrium", "plate", "--set", "material=gent", "--set", "Jlim=0"],
     ["Jlim = 0", "must be > 0"]),
    ("Jlim negative", eq("plate", material="gent", Jlim=-3), ["equilibrium", "plate", "--set", "material=gent", "--set", "Jlim=-3"],
     ["Jlim = -3", "must be > 0"]),
    ("eps zero", eq("balloon", eps=0), ["equilibrium", "balloon", "--set", "eps=0"], ["eps = 0", "must be > 0"]),
    ("mu negative", eq("balloon", mu=-1), ["equilibrium", "balloon", "--set", "mu=-1"], ["mu = -1", "must be > 0"]),
    ("unknown material", eq("plate", material="rubber"), ["equilibrium", "plate", "--set", "material=rubber"],
     ["material = 'rubber'", "must be one of", "mooney_rivlin"]),
    ("unknown parameter", eq("plate", zeta=1.0), ["equilibrium", "plate", "--set", "zeta=1"],
     ["parameter 'zeta'", "no such parameter", "it has nodes, H"]),
    ("unknown scene", lambda: build_scene("cube"), ["equilibrium", "cube"], ["scene 'cube'", "unknown", "available: plate"]),
    ("Rs equal Rb", eq("torus", Rs=10.0), ["equilibrium", "torus", "--set", "Rs=10"], ["Rs = 10", "must be < Rb = 10"]),
    ("Rs beyond Rb", eq("torus", Rs=12.0), ["equilibrium", "torus", "--set", "Rs=12"], ["Rs = 12", "must be < Rb = 10"]),
    ("Rb zero", eq("torus", Rb=0), ["equilibrium", "torus", "--set", "Rb=0"], ["Rb = 0", "must be > 0"]),
    ("E_hat and voltage", eq("balloon", E_hat=0.1, voltage=5.0),
     ["equilibrium", "balloon", "--set", "E_hat=0.1", "--set", "voltage=5"], ["E_hat = 0.1", "voltage = 5", "not both"]),
    ("pressure nan", lambda: equilibrium(build_scene("balloon", nodes=11), {"pressure": NAN}),
     ["equilibrium", "balloon", "--pressure", "nan"], ["pressure = nan", "must be finite"]),
    ("pressure string", eq("balloon", pressure="lots"), ["equilibrium", "balloon", "--pressure", "lots"],
     ["pressure = 'lots'", "must be a number"]),
    ("set without =", lambda: parse_sets(["oops"]), ["equilibrium", "plate", "--set", "oops"],
     ["--set 'oops'", "must be NAME=VALUE"]),
    ("set without name", lambda: parse_sets(["=5"]), ["equilibrium", "plate", "--set", "=5"], ["--set '=5'", "NAME=VALUE"]),
    ("set without value", lambda: parse_sets(["R="]), ["equilibrium", "plate", "--set", "R="], ["--set 'R='", "NAME=VALUE"]),
    ("grid malformed", lambda: parse_axis("pressure=0:1"),
     ["sweep", "balloon", "--grid", "pressure=0:1", "--out", "x.csv"], ["--grid 'pressure=0:1'", "NAME=START:STOP:COUNT"]),
    ("grid count zero", lambda: parse_axis("pressure=0:1:0"),
     ["sweep", "balloon", "--grid", "pressure=0:1:0", "--out", "x.csv"], ["pressure COUNT = 0", ">= 1"]),
    ("grid unknown parameter", lambda: make_job("equilibrium", "balloon", {}, {"zeta": [1]}),
     ["sweep", "balloon", "--grid", "zeta=1,2", "--out", "x.csv"], ["--grid 'zeta'", "no such parameter"]),
    ("grid bad value", lambda: make_job("equilibrium", "balloon", {}, {"H": [0.1, -1]}),
     ["sweep", "balloon", "--grid", "H=0.1,-1", "--out", "x.csv"], ["H = -1", "must be > 0"]),
    ("grid and set", lambda: make_job("equilibrium", "balloon", {"H": "0.1"}, {"H": [0.2]}),
     ["sweep", "balloon", "--grid", "H=0.2", "--set", "H=0.1", "--out", "x.csv"], ["'H'", "both"]),
    ("unknown job", lambda: make_job("dance", "balloon"),
     ["sweep", "balloon", "--grid", "H=0.2", "--job", "dance", "--out", "x.csv"], ["job 'dance'", "available: equilibrium"]),
    ("workers zero", lambda: sweep(dict, {"a": [1]}, "x.csv", workers=0),
     ["sweep", "balloon", "--grid", "H=0.2", "--workers", "0", "--out", "x.csv"], ["workers = 0", ">= 1"]),
    ("timeout negative", lambda: sweep(dict, {"a": [1]}, "x.csv", timeout=-1),
     ["sweep", "balloon", "--grid", "H=0.2", "--timeout", "-1", "--out", "x.csv"], ["timeout = -1", "must be > 0"]),
    ("timeout string", lambda: sweep(dict, {"a": [1]}, "x.csv", timeout="soon"),
     ["sweep", "balloon", "--grid", "H=0.2", "--timeout", "soon", "--out", "x.csv"], ["timeout = 'soon'", "must be"]),
    ("bad scheduler", lambda: sweep(dict, {"a": [1]}, "x.csv", scheduler="udp://x:1"),
     ["sweep", "balloon", "--grid", "H=0.2", "--scheduler", "udp://x:1", "--out", "x.csv"],
     ["scheduler = 'udp://x:1'", "tcp://HOST:PORT"]),
    ("out folder missing", lambda: sweep(dict, {"a": [1]}, "no/such/x.csv"),
     ["sweep", "balloon", "--grid", "H=0.2", "--out", "no/such/x.csv"], ["out = 'no/such/x.csv'", "does not exist"]),
    ("branch truncated", load(load_points, "truncated.npz"), ["trace", "balloon", "--restart", "truncated.npz"],
     ["branch file 'truncated.npz': cannot be read", "not a zip file"]),
    ("branch not a zip", load(load_points, "text.npz"), ["trace", "balloon", "--restart", "text.npz"],
     ["branch file 'text.npz': cannot be read"]),
    ("branch empty", load(load_points, "empty.npz"), ["trace", "balloon", "--restart", "empty.npz"],
     ["branch file 'empty.npz': cannot be read"]),
    ("branch missing", load(load_points, "nothing.npz"), ["trace", "balloon", "--restart", "nothing.npz"],
     ["branch file 'nothing.npz': cannot be read", "No such file"]),
    ("branch of another program", load(load_points, "good.npz"), ["trace", "balloon", "--restart", "good.npz"],
     ["branch file 'good.npz': has no 'lam' array", "not a snapmem branch"]),
    ("trajectory truncated", load(Trajectory.load, "truncated.npz"), ["replay", "truncated.npz", "--out", "a.gif"],
     ["trajectory file 'truncated.npz': cannot be read", "not a zip file"]),
    ("trajectory with pickled objects", load(Trajectory.load, "objects.npz"), ["replay", "objects.npz", "--out", "a.gif"],
     ["trajectory file 'objects.npz': cannot be read", "allow_pickle=False"]),
    ("trajectory of another program", load(Trajectory.load, "good.npz"), ["replay", "good.npz", "--out", "a.gif"],
     ["trajectory file 'good.npz': has no 't' array", "not a snapmem trajectory"]),
    # issue 13, crashes and tracebacks: each row failed on 9b6cacc (a traceback, exit 0 or a wrong name)
    ("out folder missing, checked before the run", None, ["simulate", "balloon", "--set", "nodes=11", "--quiet",
                                                          "--out", "nodir/x.npz"], ["--out = 'nodir/x.npz'", "does not exist"]),
    ("trace out in a missing folder", None, ["trace", "balloon", "--set", "nodes=11", "--out", "nodir/x.csv"],
     ["--out = 'nodir/x.csv'", "does not exist"]),
    ("out is a folder", None, ["trace", "balloon", "--set", "nodes=11", "--out", "."], ["--out = '.'", "is a folder"]),
    ("plot not a figure", None, ["trace", "balloon", "--set", "nodes=11", "--plot", "x.csv"],
     ["--plot = 'x.csv'", "must end in .png"]),
    ("t-end zero", None, ["simulate", "balloon", "--set", "nodes=11", "--t-end", "0"], ["--t-end = 0", ">= 1e-09"]),
    ("t-end negative", None, ["simulate", "pump", "--t-end", "-5"], ["--t-end = -5", ">= 1e-09"]),
    ("t-end below the shortest step", None, ["simulate", "pump", "--t-end", "1e-12"], ["--t-end = 1e-12", ">= 1e-09"]),
    ("frames negative names frames", None, ["simulate", "pump", "--frames", "-5"], ["--frames = -5", ">= 0"]),
    ("replay fps zero", None, ["replay", "good.npz", "--out", "a.gif", "--fps", "0"], ["--fps = 0", ">= 1"]),
    ("replay fps negative", None, ["replay", "good.npz", "--out", "a.gif", "--fps", "-3"], ["--fps = -3", ">= 1"]),
    ("nodes 1e308", eq("balloon", nodes=1e308), ["equilibrium", "balloon", "--set", "nodes=1e308"],
     ["nodes = 1e+308", "<= 1e+06"]),
    ("nodes 1e7 with the memory estimate", eq("balloon", nodes=10_000_000),
     ["equilibrium", "balloon", "--set", "nodes=10000000"], ["nodes = 10000000", "12 GB"]),
    ("E_hat 1e308", eq("balloon", E_hat=1e308), ["equilibrium", "balloon", "--set", "E_hat=1e308"],
     ["E_hat = 1e+308", "magnitude"]),
    ("voltage 1e308", eq("balloon", voltage=1e308), ["equilibrium", "balloon", "--set", "voltage=1e308"],
     ["voltage = 1e+308", "magnitude"]),
    ("R 1e-308", eq("balloon", R=1e-308), ["equilibrium", "balloon", "--set", "R=1e-308"], ["R = 1e-308", "magnitude"]),
    ("c1 1e308 names c1", eq("balloon", c1=1e308), ["equilibrium", "balloon", "--set", "c1=1e308"],
     ["c1 = 1e+308", "magnitude"]),
    ("grid of 1e12 designs", lambda: parse_axis("pressure=0:1:1000000") and sweep(
        dict, {"a": list(range(10 ** 6)), "b": list(range(10 ** 6))}, "x.csv"),
     ["sweep", "balloon", "--grid", "pressure=0:1:1000000", "--grid", "H=0.1:1:1000000", "--out", "x.csv"],
     ["1e+12 designs", "at most 1e+07"]),
    ("set name on a ball scene", None, ["simulate", "ball_drop", "--set", "name=foo"], ["--set name=foo", "leave name out"]),
    ("pump schedule out of order, no numpy reprs", eq("pump", t_up=20, t_hold=10),
     ["simulate", "pump", "--set", "t_up=20", "--set", "t_hold=10"], ["t_hold = 10 s", "t_up <= t_hold <= t_down"]),
    ("duplicate set", lambda: parse_sets(["nodes=11", "nodes=12"]), ["equilibrium", "balloon", "--set", "nodes=11",
                                                                    "--set", "nodes=12"], ["'nodes'", "given twice"]),
    ("set pressure and --pressure", None, ["equilibrium", "balloon", "--set", "pressure=0.01", "--pressure", "0.02"],
     ["--set pressure=0.01", "--pressure 0.02", "not both"]),
    ("Rs and aspect_ratio", eq("torus", Rs=1.0, aspect_ratio=0.1),
     ["equilibrium", "torus", "--set", "Rs=1", "--set", "aspect_ratio=0.1"], ["Rs = 1", "aspect_ratio = 0.1", "not both"]),
    ("fixed not integers", lambda: Scene(build_scene("balloon", nodes=11).meridian, 0.1, [], fixed=[0, 1.5]), None,
     ["fixed[1] = 1.5", "must be an integer"]),
    ("underscored digits", eq("balloon", nodes="1_0"), ["equilibrium", "balloon", "--set", "nodes=1_0"],
     ["nodes = '1_0'", "must be a number"]),
    ("full-width digits", eq("balloon", nodes="１２"), ["equilibrium", "balloon", "--set", "nodes=１２"],
     ["nodes = '１２'", "must be a number"]),
    # API only: inputs that have no command-line form
    ("meridian self-intersecting", lambda: Meridian([1.0, 2.0, 2.0, 1.0], [0.0, 1.0, 0.0, 1.0]), None,
     ["meridian is self-intersecting", "edges 0 and 2 cross"]),
    ("meridian crosses the axis", lambda: Meridian([1.0, -1.0, 2.0], [0.0, 1.0, 2.0]), None, ["r[1] = -1", ">= 0"]),
    ("meridian touches the axis inside", lambda: Meridian([1.0, 0.0, 2.0], [0.0, 1.0, 2.0]), None,
     ["r = 0 at node(s) [1]", "only the end nodes"]),
    ("meridian 2D arrays", lambda: Meridian(np.ones((2, 2)), np.ones((2, 2))), None, ["shapes (2, 2)", "1D arrays"]),
    ("meridian lengths differ", lambda: Meridian([1.0, 2.0, 3.0], [0.0, 1.0]), None, ["shapes (3,) and (2,)"]),
    ("meridian nan", lambda: Meridian([1.0, NAN, 2.0], [0.0, 1.0, 2.0]), None, ["must be finite"]),
    ("meridian 2 nodes", lambda: Meridian([1.0, 2.0], [0.0, 1.0]), None, ["nodes = 2", ">= 3"]),
    ("Gent Jlim zero", lambda: Gent(1.0, 0.0), None, ["Jlim = 0", "> 0"]),
    ("Mooney-Rivlin c1 negative", lambda: MooneyRivlin(-1.0, 0.1), None, ["c1 = -1"]),
    ("q0 wrong shape", solve_with(q0=np.zeros(5)), None, ["q0: shape (5,)", "must be (22,)"]),
    ("q0 nan", solve_with(q0=np.full(22, NAN)), None, ["q0[0] = nan", "must be finite"]),
    ("q0 string", solve_with(q0="abc"), None, ["q0 = 'abc'", "shape (22,)"]),
    ("loads not a mapping", lambda: equilibrium(build_scene("balloon", nodes=11), [0.1]), None,
     ["loads = [0.1]", "must be a mapping"]),
    ("unknown load", lambda: equilibrium(build_scene("balloon", nodes=11), {"voltage": 1.0}), None,
     ["load 'voltage'", "no such load", "['pressure']"]),
    ("tolerance zero", lambda: NewtonOptions(tol=0), None, ["tol = 0", "> 0"]),
    ("max_iterations zero", lambda: NewtonOptions(max_iterations=0), None, ["max_iterations = 0", ">= 1"]),
    # found by the fuzz (exit 1 after 2000 steps on ba9bbf1): the loading cannot go up to a peak below
    # where the snap settled; refused once the limit point (p_hat 0.0142464) is known
    ("hysteresis peak below the snap", lambda: _hysteresis_peak(0.0),
     ["hysteresis", "balloon", "--set", "nodes=11", "--peak", "0"], ["peak = 0.0", "must be > 0.01426"]),
]


def _hysteresis_peak(peak):
    from snapmem.continuation.hysteresis import hysteresis
    return hysteresis(build_scene("balloon", nodes=11), "pressure", peak=peak)

# (id, API call returning an Equilibrium, CLI argv, status, words of the reason)
RESULTS = [
    ("voltage beyond any equilibrium", lambda: equilibrium(build_scene("balloon", nodes=11, E_hat=5.0)),
     ["equilibrium", "balloon", "--set", "nodes=11", "--set", "E_hat=5"], "no_equilibrium",
     ["no equilibrium on the load path beyond voltage"]),
    ("Gent past its lock at the start", past_gent_lock, None, "left_domain",
     ["left the model's domain", "starting state", "Gent(mu=1.0, Jlim=1.0)"]),
    # found by the soak: the snap-through trace's root finder gave up and raised (scipy RuntimeError)
    ("suction on a thin balloon", lambda: equilibrium(build_scene(
        "balloon", nodes=13, material="neo_hookean", c1=0.35253144268545156, H=0.03710449855837486,
        pressure=-0.0013605419352743825)),
     ["equilibrium", "balloon", "--set", "nodes=13", "--set", "material=neo_hookean", "--set", "c1=0.35253144268545156",
      "--set", "H=0.03710449855837486", "--pressure", "-0.0013605419352743825"],
     "no_equilibrium", ["no equilibrium on the load path beyond pressure"]),
]


def test_the_table_is_long_enough():
    assert len([row for row in ERRORS if row[2] is not None]) >= 30
    assert len(ERRORS) + len(RESULTS) >= 50


@pytest.mark.parametrize("name,call,argv,words", ERRORS, ids=[row[0] for row in ERRORS])
def test_api_raises_one_clear_error(name, call, argv, words, tmp_path, monkeypatch):
    if call is None:
        pytest.skip("a command-line input only")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SnapmemError) as info:
        call()
    message = str(info.value)
    for word in words:
        assert word in message
    assert "\n" not in message


@pytest.mark.parametrize("name,call,argv,words", [row for row in ERRORS if row[2] is not None],
                         ids=[row[0] for row in ERRORS if row[2] is not None])
def test_cli_prints_one_line_and_exits_2(name, call, argv, words, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    write_files()
    assert main(argv) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("snapmem: error:"), err
    assert "Traceback" not in captured.err + captured.out
    for word in words:
        assert word in err
    assert not (tmp_path / "x.csv").exists()        # a sweep with bad input writes nothing


@pytest.mark.parametrize("name,call,argv,status,words", RESULTS, ids=[row[0] for row in RESULTS])
def test_no_answer_is_a_result_with_a_status(name, call, argv, status, words, capsys):
    result = call()
    assert not result.converged and result.report.status == status
    for word in words:
        assert word in result.report.reason
    assert np.all(np.isfinite(result.q))                       # the last good state, never NaN
    assert all(np.isfinite(v) for v in result.measures().values() if isinstance(v, float))
    if argv is not None:
        assert main(argv) == 1
        captured = capsys.readouterr()
        assert "Traceback" not in captured.err + captured.out
        assert "converged: False" in captured.out
        for word in words:
            assert word in captured.out


def test_in_a_subprocess_no_traceback_and_debug_shows_it():
    quiet = subprocess.run([sys.executable, "-m", "snapmem.cli", "equilibrium", "balloon", "--set", "nodes=many"],
                           capture_output=True, text=True)
    assert quiet.returncode == 2 and "Traceback" not in quiet.stderr
    assert quiet.stderr.strip() == "snapmem: error: nodes = 'many': must be a number"
    loud = subprocess.run([sys.executable, "-m", "snapmem.cli", "--debug", "equilibrium", "balloon", "--set",
                           "nodes=many"], capture_output=True, text=True)
    assert loud.returncode != 0 and "Traceback" in loud.stderr and "SnapmemError" in loud.stderr
