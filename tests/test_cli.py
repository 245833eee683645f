"""The command line prints what the issues promise, with numbers a user can check."""

import pytest

from snapmem.reference import exact
from snapmem.cli import main


def parse(text):
    return dict(line.split(": ", 1) for line in text.strip().splitlines())


def test_equilibrium_balloon_prints_measures_and_report(capsys):
    assert main(["equilibrium", "balloon", "--set", "nodes=101", "--set", "E_hat=0.1538", "--pressure", "0.012"]) == 0
    out = parse(capsys.readouterr().out)
    for key in ("volume", "u_max", "stretch_max", "converged", "iterations", "residual_norm", "reason"):
        assert key in out
    assert out["converged"] == "True"
    lam = exact.balloon_stretch(0.012, E_hat=0.1538)
    assert float(out["stretch"]) == pytest.approx(lam, rel=2e-4)
    assert float(out["u_max"]) == pytest.approx(2 * 10 * (lam - 1), rel=2e-3)   # south pole fixed: north pole moves 2R(lam-1)


def test_scenes_lists_parameters_with_units(capsys):
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    assert "balloon:" in out and "torus:" in out and "plate:" in out
    assert "Rs = 2.0 [m]" in out and "nodes = 101" in out
