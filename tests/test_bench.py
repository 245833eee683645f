"""The benchmark studies run (on small settings) and measure what they say."""

import importlib.util
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from snapmem.reference import exact
from snapmem.bench import balloon_curve, newton_floor

STUDIES = Path(__file__).resolve().parents[1] / "studies"


def _study(name):
    spec = importlib.util.spec_from_file_location(name, STUDIES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("scene", ["balloon", "torus"])
def test_newton_floor_times_the_iteration_against_both_solves(scene):
    r = newton_floor(201, scene)
    assert r["factorisation"] == "BandedLDLT"                  # a stable state: the compiled solve
    assert r["iteration_s"] > r["own_solve_s"] > 0 and r["solve_s"] > 0
    assert r["ratio"] == pytest.approx(r["iteration_s"] / r["solve_s"])


def test_bench_balloon_curve_quick_locates_the_limit_point(tmp_path):
    table = _study("bench_balloon_curve").main(["--quick", "--nodes", "51", "--out", str(tmp_path / "bc.csv")])
    assert table["limit_located"].all() and (tmp_path / "bc.csv.json").exists()
    assert (table["p_limit_rel_error"].abs() < 2e-3).all()       # the N = 51 mesh's error, ~N^-2
    assert (table["assemblies"] < 150).all()


def test_balloon_curve_reports_the_limit_pressure_of_the_mesh():
    r = balloon_curve(nodes=51, repeats=1)
    assert r["limit_located"] and r["p_limit"] == pytest.approx(exact.balloon_limit_point()[1], rel=2e-3)


def test_bench_newton_quick_runs(tmp_path):
    table = _study("bench_newton").main(["--quick", "--out", str(tmp_path / "bn.csv")])
    assert set(zip(table["scene"], table["nodes"])) == {(s, n) for s in ("balloon", "torus") for n in (101, 1001)}
    assert np.allclose(table["ratio"], table["iteration_s"] / table["solve_s"], rtol=1e-12)
    assert np.allclose(table["ratio_own"], table["iteration_s"] / table["own_solve_s"], rtol=1e-12)
    assert np.allclose(table["iteration_us_per_dof"], 1e6 * table["iteration_s"] / table["dofs"], rtol=1e-12)
    saved = pd.read_csv(tmp_path / "bn.csv")                     # the file holds what was measured
    assert list(saved.columns) == list(table.columns) and np.allclose(saved["ratio"], table["ratio"], rtol=1e-12)
