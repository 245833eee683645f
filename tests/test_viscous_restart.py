"""Continuing a run (issue 15): a viscoelastic run split in two, the second part started from the
first's end (``simulate(resume=meta['resume'])``, ``snapmem simulate --restart``), is the one run:
the state, the next step, the scheme's history and the networks' internal stretches carry over."""

import numpy as np
import pytest

from snapmem.catalog.registry import build_scene
from snapmem.cli import main
from snapmem.dynamics.driver import simulate
from snapmem.dynamics.options import DynamicsOptions
from snapmem.dynamics.trajectory import Trajectory
from snapmem.errors import SnapmemError
from snapmem.solvers.newton import NewtonOptions

P, SPLIT, END = 0.012, 0.3, 0.6
LOADS = {"pressure": [(0.0, 0.0), (0.005, P), (SPLIT, P), (END, P)]}     # a kink at the split: a step lands there


@pytest.fixture(scope="module")
def scene():
    return build_scene("balloon", nodes=21, viscous_mu=0.5, relaxation_time=0.2)


@pytest.mark.parametrize("scheme, adaptive", [("bdf2", False), ("bdf2", True), ("midpoint", True)])
def test_a_run_split_in_two_is_the_one_run(scene, scheme, adaptive, tmp_path):
    options = DynamicsOptions(scheme=scheme, dt=0.01, adaptive=adaptive, tol=1e-3, save_interval=0.0)

    def run(t_end, resume=None):
        return simulate(scene, LOADS, t_end, rho=1e-6, damping=1e3, options=options, resume=resume)

    whole = run(END)
    first = run(SPLIT)
    first.save(tmp_path / "first.npz")                      # through the file, as --restart reads it
    second = run(END, resume=Trajectory.load(tmp_path / "first.npz").meta["resume"])
    assert first["t"][-1] == second["t"][0] == SPLIT
    assert first.meta["steps"] + second.meta["steps"] == whole.meta["steps"]
    for key in ("t", "q", "v", "xi", "dissipation", "potential"):
        joined = np.concatenate([first[key], second[key][1:]])
        assert joined.shape == whole[key].shape, key
        scale = max(np.abs(whole[key]).max(), 1.0)
        assert np.abs(joined - whole[key]).max() <= 1e-12 * scale, key
    assert np.all(whole["xi"][-1] > first["xi"][-1])          # the networks kept creeping after the split


def test_simulate_restart_on_the_command_line(tmp_path, capsys):
    common = ["simulate", "balloon", "--set", "nodes=21", "--set", f"pressure={P}", "--set", "viscous_mu=0.5",
              "--set", "relaxation_time=0.2", "--quiet"]
    assert main(common + ["--t-end", "0.4", "--out", str(tmp_path / "whole.npz")]) == 0
    assert main(common + ["--t-end", "0.2", "--out", str(tmp_path / "a.npz")]) == 0
    assert main(common + ["--t-end", "0.4", "--restart", str(tmp_path / "a.npz"), "--out", str(tmp_path / "b.npz")]) == 0
    whole, a, b = (Trajectory.load(tmp_path / f"{n}.npz") for n in ("whole", "a", "b"))
    assert b["t"][0] == a["t"][-1] and b["t"][-1] == whole["t"][-1] == 0.4
    # the command's continuation is the API's from the saved end state ...
    held = build_scene("balloon", nodes=21, pressure=P, viscous_mu=0.5, relaxation_time=0.2)
    api = simulate(held, lambda t: {"pressure": P}, 0.4, rho=1.0, damping=1.0, resume=a.meta["resume"],
                   options=DynamicsOptions(**{**b.meta["options"], "newton": NewtonOptions(**b.meta["options"]["newton"])}))
    for key in ("q", "xi"):
        assert np.abs(b[key] - api[key]).max() <= 1e-13 * np.abs(api[key]).max(), key
    # ... and the adaptive steps of the whole run, which did not land on t = 0.2, differ at its tolerance
    assert np.abs(b["q"][-1] - whole["q"][-1]).max() <= 1e-5 * np.abs(whole["q"][-1]).max()
    assert np.all(b["xi"][-1] > a["xi"][-1])
    capsys.readouterr()
    # another scene's parameters, or an end before the saved one: one clear error, exit 2
    assert main(common[:-1] + ["--set", "relaxation_time=0.3", "--quiet", "--t-end", "0.4", "--restart",
                               str(tmp_path / "a.npz")]) == 2
    assert "relaxation_time" in capsys.readouterr().err
    assert main(common + ["--t-end", "0.1", "--restart", str(tmp_path / "a.npz")]) == 2
    assert "past its end" in capsys.readouterr().err


def test_restoring_networks_of_another_shape_is_refused(scene):
    other = build_scene("balloon", nodes=11, viscous_mu=0.5, relaxation_time=0.2)
    options = DynamicsOptions(scheme="bdf2", dt=0.01, adaptive=False, save_interval=0.0)
    first = simulate(scene, LOADS, 0.05, rho=1e-6, damping=1e3, options=options)
    resume = {**first.meta["resume"], "q": other.reference_state(), "v": np.zeros_like(other.reference_state())}
    with pytest.raises(SnapmemError, match="internal stretches"):
        simulate(other, LOADS, 0.1, rho=1e-6, damping=1e3, options=options, resume=resume)
