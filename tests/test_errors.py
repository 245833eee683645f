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
