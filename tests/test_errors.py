"""Bad input: one clear message naming the parameter, its value and what is allowed."""

import subprocess
import sys

import numpy as np
import pytest

from snapmem import SnapmemError, build_scene, disc, sphere, torus, Meridian
from snapmem.cli import main
from snapmem.model.materials import Gent, MooneyRivlin

# (scene, parameters, words the message must contain)
BAD_SCENES = [
    ("balloon", {"H": 0}, ["H = 0", "> 0"]),
    ("balloon", {"H": -1.0}, ["H = -1", "> 0"]),
    ("torus", {"Rs": 10.0}, ["Rs = 10", "< Rb = 10"]),
    ("torus", {"Rs": 12.0}, ["Rs = 12", "< Rb"]),
    ("plate", {"nodes": 2}, ["nodes = 2", ">= 3"]),
    ("plate", {"material": "gent", "Jlim": 0.0}, ["Jlim = 0", "> 0"]),
    ("plate", {"material": "gent", "Jlim": -3.0}, ["Jlim = -3", "> 0"]),
    ("plate", {"material": "rubber"}, ["material = 'rubber'", "mooney_rivlin"]),
    ("plate", {"bogus": 1.0}, ["parameter 'bogus'", "no such parameter"]),
    ("balloon", {"R": float("nan")}, ["R = nan", "finite"]),
    ("balloon", {"R": float("inf")}, ["R = inf", "finite"]),
    ("balloon", {"nodes": 10.5}, ["nodes = 10.5", "integer"]),
    ("balloon", {"c1": "abc"}, ["c1 = 'abc'", "number"]),
    ("balloon", {"E_hat": 0.1, "voltage": 5.0}, ["E_hat", "voltage", "not both"]),
]


@pytest.mark.parametrize("scene,params,words", BAD_SCENES)
def test_bad_scene_parameters_raise_clear_errors(scene, params, words):
    with pytest.raises(SnapmemError) as info:
        build_scene(scene, **params)
    for w in words:
        assert w in str(info.value)


def test_unknown_scene():
    with pytest.raises(SnapmemError, match="scene 'cube': unknown; available: plate"):
        build_scene("cube")


@pytest.mark.parametrize("make,words", [
    (lambda: disc(-1.0, 10), ["R = -1"]),
    (lambda: sphere(1.0, 2), ["nodes = 2", ">= 3"]),
    (lambda: torus(1.0, 1.5, 20), ["Rs = 1.5", "< Rb = 1"]),
    (lambda: Meridian([1.0, -1.0, 2.0], [0.0, 1.0, 2.0]), ["r[1] = -1", ">= 0"]),
    (lambda: Meridian([1.0, 2.0, 2.0, 1.0], [0.0, 1.0, 0.0, 1.0]), ["self-intersecting"]),
    (lambda: Meridian([1.0, 0.0, 2.0], [0.0, 1.0, 2.0]), ["r = 0 at node(s) [1]"]),
    (lambda: Meridian([1.0, 2.0], [0.0, 1.0]), ["nodes = 2"]),
    (lambda: Meridian(np.ones((2, 2)), np.ones((2, 2))), ["1D arrays"]),
    (lambda: Gent(1.0, 0.0), ["Jlim = 0"]),
    (lambda: MooneyRivlin(-1.0, 0.1), ["c1 = -1"]),
])
def test_bad_api_input(make, words):
    with pytest.raises(SnapmemError) as info:
        make()
    for w in words:
        assert w in str(info.value)


@pytest.mark.parametrize("argv,words", [
    (["equilibrium", "balloon", "--set", "H=-1"], ["H = -1.0", "> 0"]),
    (["equilibrium", "torus", "--set", "Rs=12"], ["Rs = 12", "< Rb"]),
    (["equilibrium", "cube"], ["scene 'cube'"]),
    (["equilibrium", "plate", "--set", "nodes=2"], ["nodes = 2"]),
    (["equilibrium", "plate", "--set", "material=gent", "--set", "Jlim=0"], ["Jlim = 0"]),
    (["equilibrium", "plate", "--set", "oops"], ["--set 'oops'", "NAME=VALUE"]),
    (["equilibrium", "plate", "--set", "zeta=1"], ["parameter 'zeta'"]),
    (["equilibrium", "plate", "--pressure", "lots"], ["pressure = 'lots'"]),
    (["frobnicate"], ["invalid choice"]),
])
def test_cli_bad_input_is_one_line_and_exit_2(argv, words, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("snapmem: error:")
    for w in words:
        assert w in err


def test_cli_in_a_subprocess_prints_no_traceback():
    out = subprocess.run([sys.executable, "-m", "snapmem.cli", "equilibrium", "torus", "--set", "Rs=20"],
                         capture_output=True, text=True)
    assert out.returncode == 2
    assert "Traceback" not in out.stderr and "Rs = 20" in out.stderr


def test_cli_debug_shows_the_traceback():
    with pytest.raises(SnapmemError):
        main(["--debug", "equilibrium", "torus", "--set", "Rs=20"])


# ------------------------------------------------------------------------------------------
# issue 13: each test below failed on 9b6cacc (a traceback, a KeyError or a partial file)
def _cli(argv, capsys):
    code = main(argv)
    captured = capsys.readouterr()
    assert "Traceback" not in captured.out + captured.err
    return code, captured.out, captured.err.strip()


def test_debug_and_verbose_after_the_command(capsys):
    assert _cli(["scenes", "--debug", "-v"], capsys)[0] == 0
    with pytest.raises(SnapmemError, match="nodes = 'x'"):          # --debug shows the error, wherever it is
        main(["equilibrium", "balloon", "--set", "nodes=x", "--debug"])


def test_fold_without_any_limit_point_is_a_table(capsys):
    """H = 0.1 and 0.5 on a plate: no limit point up to stretch 12, so exists is False in both rows."""
    code, out, _ = _cli(["fold", "plate", "--vary", "H=0.1,0.5", "--set", "nodes=21"], capsys)
    assert code == 0
    rows = [line.split() for line in out.splitlines()[1:]]
    assert [row[0] for row in rows] == ["0.1", "0.5"] and all(row[1] == "NaN" and row[2] == "False" for row in rows)


def test_trace_restart_checks_the_file(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert _cli(["trace", "balloon", "--set", "nodes=11", "--max-steps", "5", "--out", "b.csv"], capsys)[0] == 1   # max steps: not reached
    code, _, err = _cli(["trace", "balloon", "--set", "nodes=21", "--restart", "b.npz"], capsys)
    assert code == 2 and "saved with 11 nodes" in err and "has 21" in err and "--set nodes=11" in err
    arrays = dict(np.load("b.npz"))
    np.savez("bad_meta.npz", **{**arrays, "meta": np.array("{not json")})
    code, _, err = _cli(["trace", "balloon", "--set", "nodes=11", "--restart", "bad_meta.npz"], capsys)
    assert code == 2 and "not a snapmem branch file" in err
    np.savez("nan.npz", **{**arrays, "q": np.full_like(arrays["q"], np.nan)})
    code, _, err = _cli(["trace", "balloon", "--set", "nodes=11", "--restart", "nan.npz"], capsys)
    assert code == 2 and "non-finite" in err
    np.savez("no_q.npz", **{k: v for k, v in arrays.items() if k != "q"})
    code, _, err = _cli(["trace", "balloon", "--set", "nodes=11", "--restart", "no_q.npz"], capsys)
    assert code == 2 and "'q' must be" in err
    code, out, _ = _cli(["trace", "balloon", "--set", "nodes=11", "--max-steps", "5", "--restart", "b.npz"], capsys)
    assert code == 1 and "status:" in out          # the good file still restarts (5 steps: target not reached)


@pytest.mark.parametrize("arrays,words", [
    ({"t": np.array([]), "r": np.zeros((0, 3)), "z": np.zeros((0, 3))}, ["'t' must be a non-empty 1D array"]),
    ({"t": np.array([0.0, 1.0]), "r": np.full((2, 3), np.nan), "z": np.zeros((2, 3))}, ["'r' has non-finite"]),
    ({"t": np.array([0.0, 1.0]), "r": np.ones((3, 3)), "z": np.ones((2, 3))}, ["'r' has shape (3, 3)", "(2, N >= 2)"]),
    ({"t": np.array([0.0, 1.0]), "r": np.ones((2, 3)), "z": np.ones((2, 3)), "volume": np.ones(5)},
     ["'volume' has shape (5,)"]),
    ({"t": np.array(["a", "b"]), "r": np.ones((2, 3)), "z": np.ones((2, 3))}, ["'t' must be"]),
    ({"t": np.array([1.0, 0.0]), "r": np.ones((2, 3)), "z": np.ones((2, 3))}, ["must not decrease"]),
], ids=["empty", "nan", "mismatched", "series mismatched", "foreign dtype", "time backwards"])
def test_replay_refuses_arrays_it_cannot_draw_and_leaves_no_file(arrays, words, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    np.savez("t.npz", **arrays)
    code, _, err = _cli(["replay", "t.npz", "--out", "a.gif"], capsys)
    assert code == 2 and len(err.splitlines()) == 1
    assert all(word in err for word in words), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.npz"]


def test_replay_writes_the_gif_whole(tmp_path, monkeypatch, capsys):
    """A good trajectory: the GIF appears complete (3 frames) under its name, no temporary beside it."""
    from PIL import Image
    monkeypatch.chdir(tmp_path)
    r = np.array([[0.0, 1.0, 0.0]] * 3) * np.array([[1.0], [1.1], [1.2]])
    np.savez("t.npz", t=np.array([0.0, 1.0, 2.0]), r=r, z=np.array([[-1.0, 0.0, 1.0]] * 3), volume=np.ones(3))
    assert _cli(["replay", "t.npz", "--out", "a.gif", "--frames", "3"], capsys)[0] == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.gif", "t.npz"]
    assert Image.open("a.gif").n_frames == 3


def test_trace_memory_is_estimated_before_allocating(monkeypatch):
    """2000 stored states of 1e6 nodes: 1e6 x (1200 + 32 x 2000) B = 65.2 GB, refused on a 23 GB machine."""
    import snapmem.model.parameters as parameters
    assert parameters.memory_estimate(10 ** 6, 2000) == pytest.approx(65.2e9)
    monkeypatch.setattr(parameters, "available_memory", lambda: 23e9)
    with pytest.raises(SnapmemError, match=r"trace: needs about 65.2 GB .* 23 GB is available"):
        parameters.check_memory("trace", 10 ** 6, 2000)
    assert parameters.check_memory("trace", 10 ** 4, 2000) == pytest.approx(6.52e8)


def test_thin_contact_barrier_is_continued_to_an_equilibrium():
    """Gripper on a rod at 2000 Pa with dhat = 1e-5 and 1e-7 of the rod: failed ('no equilibrium
    beyond 1729.71') on 9b6cacc. Now converged, gap in (0, dhat), and the rod force converges to
    the hard-contact limit as dhat -> 0 (the 1e-3 barrier gives 274.0 N)."""
    from snapmem import equilibrium
    from snapmem.model.contact import contact_report
    forces = []
    for fraction in (1e-3, 1e-5, 1e-7):
        scene = build_scene("gripper_rod", Rw=0.04, dhat=fraction * 0.04, pressure=2000.0)
        eq = equilibrium(scene)
        report = contact_report(scene, eq.q)
        assert eq.converged and 0 < report["rod_gap"] < fraction * 0.04
        forces.append(report["rod_force"])
    assert forces[0] == pytest.approx(274.0, rel=2e-3)
    assert abs(forces[2] - forces[1]) < 1e-3 * forces[1] and abs(forces[1] - forces[0]) < 3e-3 * forces[0]
