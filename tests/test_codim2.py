"""Codimension 2 and sensitivities against the exact inflated sphere (MODEL.md section 7): cusps
of the fold curve, BP curves against the P_n criterion, the BPs' convergence to the criterion's
roots, and limit-load sensitivities against the envelope theorem and finite differences."""

import numpy as np
import pytest

from snapmem.continuation import trace
from snapmem.continuation.codim2 import singular_curve
from snapmem.continuation.folds import fold_curve, fold_special_points
from snapmem.continuation.problems import make_problem
from snapmem.continuation.sensitivity import branch_sensitivities
from snapmem.reference import exact
from snapmem.scenes import build_scene


def _stretch(branch, point):
    """The balloon's ``stretch`` probe at a point of the branch."""
    return branch.scene.measures(make_problem(branch.scene, branch.control).state(point.x, point.lam)[0])["stretch"]


def test_gent_cusp_where_the_two_limit_points_merge():
    """The fold curve in Jlim, traced by arclength through its turn, has its cusp at the Jlim
    where dp/dlam = d2p/dlam2 = 0 of the exact p(lam) (17.638)."""
    at = lambda J: build_scene("balloon", nodes=41, material="gent", Jlim=J)      # noqa: E731
    values = [20.0, 19.0, 18.0]
    table, folds = fold_curve(at, values, return_folds=True)
    special, iterations = fold_special_points(at, [15.0, 20.0], folds)
    assert list(special["kind"]) == ["CP"] and iterations > 0
    jlim, lam, p = exact.balloon_cusp_gent()
    assert jlim == pytest.approx(17.638, abs=1e-3)
    assert special["value"].iloc[0] == pytest.approx(jlim, rel=1e-4)
    assert special["limit"].iloc[0] == pytest.approx(p, rel=2e-3)
    assert abs(special["a"].iloc[0]) < 1e-9                     # the fold's normal form degenerates


def test_mooney_rivlin_cusp_ratio():
    """With mu = 2 (c1 + c2) fixed, the MR balloon's snap disappears at c2/c1 = 0.2145."""
    ratio, lam, p = exact.balloon_cusp_mooney_rivlin()
    assert ratio == pytest.approx(0.2145, abs=1e-4)
    c1 = 0.4375
    at = lambda c2: build_scene("balloon", nodes=41, mu=1.0, c1=c1, c2=c2)     # noqa: E731
    table, folds = fold_curve(at, [0.07], return_folds=True)
    special, _ = fold_special_points(at, [0.07, 0.11], folds)
    cusp = special[special["kind"] == "CP"]
    assert len(cusp) == 1
    assert cusp["value"].iloc[0] / c1 == pytest.approx(ratio, rel=1e-3)
    assert cusp["stretch_max"].iloc[0] == pytest.approx(lam, rel=5e-3)


def test_fold_where_no_value_has_a_limit_point():
    """The Mooney-Rivlin plate has no pressure maximum (MODEL.md section 6): a table of
    exists = False, not an error."""
    table = fold_curve(lambda H: build_scene("plate", nodes=21, H=H), [0.1, 0.5])
    assert list(table["exists"]) == [False, False]
    assert table["limit"].isna().all() and table["u_max"].isna().all()


def test_bifurcation_points_converge_to_the_criterion_roots():
    """At E_hat = 0.4 the sphere's P1 (pole held) and P2 modes bifurcate at the roots 1.7725 and
    2.9152 of the criterion; snapmem's critical points on the uniform branch (matched by stretch,
    whatever their kind) converge to them as the mesh is refined."""
    roots = [exact.sphere_bifurcation_stretches(n, E_hat=0.4)[0] for n in (1, 2)]
    assert roots == pytest.approx([1.7725, 2.9152], abs=1e-4)
    assert exact.sphere_bifurcation_stretches(1) == [] and exact.sphere_bifurcation_stretches(2) == []   # E_hat = 0
    nodes = (41, 81, 161)
    errors = np.empty((len(nodes), 2))
    for i, N in enumerate(nodes):
        branch = trace(build_scene("balloon", nodes=N, E_hat=0.4), "pressure", until={"stretch": 3.2})
        found = [_stretch(branch, p) for p in branch.states if p.kind.value in ("LP", "BP") and p.located]
        errors[i] = [min(found, key=lambda s: abs(s - r)) - r for r in roots]
    order = -np.polyfit(np.log(nodes), np.log(np.abs(errors)), 1)[0]
    assert np.all(np.abs(errors[-1]) < [1e-4, 0.03])
    assert order[0] > 1.8                  # P1: second order
    assert order[1] > 0.9                  # P2 under the held pole: first order (a mesh asymmetry)


def _p2_bp_curve(N):
    """The pear-shaped (P2) BP of the N-node balloon at E_hat = 0.4 followed in E_hat to 0.48."""
    at = lambda E: build_scene("balloon", nodes=N, E_hat=E)      # noqa: E731
    branch = trace(at(0.4), "pressure", until={"stretch": 3.2})
    start = min((p for p in branch.states if p.kind.value in ("LP", "BP")), key=lambda p: abs(_stretch(branch, p) - 2.95))
    phi = start.vectors[:, np.argmin(np.abs(start.eigs))]
    return start, singular_curve(at, 0.4, start.x, start.lam, phi, v_range=(0.4, 0.48), v_scale=0.1)


def test_bp_curve_follows_the_criterion_in_e_hat():
    """The pear-shaped (P2) BP, reported at its unfolded point (the mesh breaks its symmetry),
    followed in E_hat by arclength on the unfolding system R + sigma psi = 0: the curve matches
    the criterion's root at every E_hat to second order (max error 6.7e-3 at N = 41, 1.7e-3 at
    N = 81: 4.0x), while the imperfection sigma stays O(h^2)."""
    errors, imperfections = [], []
    for N in (41, 81):
        start, curve = _p2_bp_curve(N)
        assert start.kind.value == "BP" and start.symmetry_broken and start.mode == 2
        t = curve.table
        assert curve.status == "left the range of v" and t["v"].max() > 0.48 and len(t) >= 5
        exact_stretch = np.array([exact.sphere_bifurcation_stretches(2, E_hat=v)[0] for v in t["v"]])
        errors.append(np.max(np.abs(t["stretch"] - exact_stretch)))
        imperfections.append(t["imperfection"].max())
        assert t["imperfection"].iloc[0] == pytest.approx(start.measured["imperfection"], rel=1e-6)
        assert np.all(np.diff(t["stretch"]) < 0)            # higher voltage, earlier bifurcation
    assert errors[1] < 2.5e-3                                # 1.67e-3 (the mesh's fold: ~0.05)
    assert errors[0] / errors[1] > 3.5                       # second order: 3.99
    assert imperfections[0] / imperfections[1] > 3.5         # sigma = O(h^2): 2.5e-4, 6.3e-5


def test_limit_pressure_sensitivities():
    """dp_s/dE_hat from the null vector against the envelope theorem -4 (H/R) E_hat lam_LP, and
    dp_s/dc2 against a central difference of limit points located on two traced branches."""
    params = dict(nodes=81, E_hat=0.3)
    scene_with = lambda name, v: build_scene("balloon", **{**params, name: v})    # noqa: E731
    branch = trace(scene_with("E_hat", 0.3), "pressure", until={"stretch": 1.7})
    table = branch_sensitivities(branch, scene_with, ["E_hat", "c2"])
    lp = table[table["kind"] == "LP"].iloc[0]
    assert lp["dpressure_dE_hat"] == pytest.approx(exact.balloon_limit_sensitivity_e_hat(E_hat=0.3), rel=5e-4)
    h = 1e-3
    limits = [trace(scene_with("c2", 0.0625 + s), "pressure", until={"stretch": 1.7}).limit_points()["pressure"].iloc[0]
              for s in (h, -h)]
    assert lp["dpressure_dc2"] == pytest.approx((limits[0] - limits[1]) / (2 * h), rel=1e-5)


@pytest.mark.slow
def test_cli_fold_points(tmp_path):
    """``snapmem fold balloon --set material=gent --vary Jlim=... --points`` writes the cusp with a
    Jlim column (slow: below the cusp the fallback trace looks for a limit point up to the lock)."""
    import pandas as pd
    from snapmem.cli import main
    special = tmp_path / "special.csv"
    assert main(["fold", "balloon", "--set", "material=gent", "--set", "nodes=21", "--vary", "Jlim=17.5,18,20",
                 "--points", str(special)]) == 0
    cusp = pd.read_csv(special)
    assert list(cusp["kind"]) == ["CP"] and cusp["Jlim"].iloc[0] == pytest.approx(exact.balloon_cusp_gent()[0], rel=1e-3)


def test_cli_trace_sensitivity(tmp_path):
    """``trace --sensitivity`` adds dpressure_d<param> columns; a count is refused (exit 2)."""
    import pandas as pd
    from snapmem.cli import main
    points = tmp_path / "points.csv"
    assert main(["trace", "balloon", "--set", "nodes=41", "--set", "E_hat=0.2", "--until", "stretch=1.7",
                 "--sensitivity", "E_hat,c2", "--points", str(points)]) == 0
    table = pd.read_csv(points)
    assert table["dpressure_dE_hat"].iloc[0] == pytest.approx(exact.balloon_limit_sensitivity_e_hat(E_hat=0.2), rel=2e-3)
    assert "dpressure_dc2" in table
    assert main(["trace", "balloon", "--set", "nodes=41", "--sensitivity", "nodes"]) == 2


@pytest.mark.slow
def test_balloon_atlas_study_quick(tmp_path):
    """studies/balloon_atlas.py --quick: every curve lies on the exact sphere's (LP curves to
    2e-3, BP curves to 6e-5 in pressure at N = 31: the P2 curve is that of the unfolded BP, the
    P1 curve (pole held: an exact BP) that of R = 0), and the cusp is located."""
    import importlib.util
    from pathlib import Path
    path = Path(__file__).resolve().parents[1] / "studies" / "balloon_atlas.py"
    spec = importlib.util.spec_from_file_location("balloon_atlas", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    table = module.main(["--quick", "--out", str(tmp_path)])
    assert (tmp_path / "balloon_atlas.png").exists() and (tmp_path / "balloon_atlas.csv").exists()
    rel = (table["pressure"] / table["pressure_exact"] - 1).abs()
    lp = table["curve"].str.startswith("LP") & (table["plane"] == "E_hat")
    assert rel[lp].max() < 2e-3                          # second order: 1.4e-3 at N = 31, 1.9e-4 at 81
    bp = table["curve"].str.startswith("BP") & (table["v"] >= 0.37)     # off the P1 curve's vertical asymptote
    assert (table["pressure"] - table["pressure_exact"])[bp].abs().max() < 6e-5      # 2.5e-5 at N = 31
    p1, p2 = (table[table["curve"] == name] for name in ("BP P1", "BP P2"))
    assert p2["imperfection"].gt(0).all() and p1["imperfection"].isna().all()    # unfolded / exact BP curve
    cusp = table[table["kind"] == "CP"]
    assert len(cusp) == 1 and cusp["v"].iloc[0] / 0.4375 == pytest.approx(exact.balloon_cusp_mooney_rivlin()[0], rel=2e-3)
    torus = table[(table["plane"] == "aspect_ratio") & (table["v"] == 0.2)]      # the seed of the torus curve
    assert torus["lam"].iloc[0] == pytest.approx(0.040910, rel=0.02)              # converged limit (README)
    assert table[table["plane"] == "aspect_ratio"]["v"].agg(["min", "max"]).tolist() == pytest.approx([0.05, 0.9], abs=0.05)
