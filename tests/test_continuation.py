"""Continuation through limit points, against the exact balloon and between controls."""

import numpy as np
import pytest

from snapmem import build_scene, exact
from snapmem.continuation import ContinuationOptions, fold_curve, load_points, trace

E_HATS = [0.0, 0.1538, 0.2308, 0.3077]
MODEL_LIMITS = {0.0: 1.407327e-2, 0.1538: 1.335400e-2, 0.2308: 1.247040e-2, 0.3077: 1.125986e-2}


def balloon_curve_error(nodes, E_hat):
    branch = trace(build_scene("balloon", nodes=nodes, E_hat=E_hat), "pressure", until={"stretch": 4.0})
    t = branch.table
    p_exact = exact.balloon_pressure(t["stretch"], E_hat=E_hat)
    return branch, float(np.max(np.abs(t["pressure"] - p_exact)) / MODEL_LIMITS[E_hat])


@pytest.mark.parametrize("E_hat", E_HATS)
def test_balloon_curve_through_limit_point_matches_exact(E_hat):
    branch, err101 = balloon_curve_error(101, E_hat)
    t = branch.table
    assert branch.status == "stretch reached 4"
    assert t["stretch"].iloc[-1] == pytest.approx(4.0, abs=1e-9)
    assert t["stretch"].max() <= 4.0 + 1e-9 and (t["pressure"].diff() < 0).any()   # passed the fold
    assert err101 <= 1e-3
    _, err51 = balloon_curve_error(51, E_hat)
    assert 3.5 < err51 / err101 < 4.5                        # error falls as N^-2
    assert "LP" in set(branch.points["kind"])


@pytest.mark.parametrize("E_hat", E_HATS)
def test_located_limit_pressure_at_n201(E_hat):
    opts = ContinuationOptions(stop_at_first_limit=True)
    branch = trace(build_scene("balloon", nodes=201, E_hat=E_hat), "pressure", until={"stretch": 4.0}, options=opts)
    lp = branch.limit_points().iloc[0]
    assert lp["pressure"] == pytest.approx(MODEL_LIMITS[E_hat], rel=1e-4)
    assert lp["located"] and abs(lp["min_eig"]) < 1e-12          # K singular to machine precision
    t = branch.table
    i = int(np.flatnonzero(t["point"] == "LP")[0])
    # stability flips exactly at the located point: stable before, one negative eigenvalue after
    assert t["stable"].iloc[:i].all() and t["negative_eigs"].iloc[i + 1:].eq(1).all()
    assert t["pressure"].iloc[i] == t["pressure"].max()


@pytest.mark.parametrize("p_hat", [9.5e-3, 10.7e-3, 11.8e-3, 13.0e-3, 14.2e-3])
def test_voltage_control_matches_exact_with_electrical_limit(p_hat):
    scene = build_scene("balloon", nodes=101, pressure=p_hat, with_loads=("voltage",))
    branch = trace(scene, "E_hat", until={"stretch": 6.0})
    t = branch.table
    E_exact = exact.balloon_e_hat(t["stretch"].to_numpy(), p_hat)
    assert np.nanmax(np.abs(t["E_hat"] - E_exact)) < 5e-3
    if p_hat < 0.0140:                       # below the unactuated limit: an electrical limit point
        lp = branch.limit_points().iloc[0]
        lam = np.linspace(1.01, 3.0, 20001)
        assert lp["E_hat"] == pytest.approx(np.nanmax(exact.balloon_e_hat(lam, p_hat)), rel=2e-3)


def test_volume_control_traces_the_same_equilibria_without_a_jump():
    scene = build_scene("balloon", nodes=101)
    by_volume = trace(scene, "volume", until={"stretch": 3.0}).table
    by_pressure = trace(scene, "pressure", until={"stretch": 3.0}).table
    assert by_volume["stable"].all()                       # volume control: no instability at the fold
    assert by_volume["volume"].is_monotonic_increasing
    assert by_volume["stretch"].diff().max() < 0.1         # no jump
    # the same curve p(stretch), both on the exact formula to discretisation accuracy
    for t in (by_volume, by_pressure):
        assert np.max(np.abs(t["pressure"] - exact.balloon_pressure(t["stretch"]))) < 5e-6
    p_interp = np.interp(by_pressure["stretch"], by_volume["stretch"], by_volume["pressure"])
    assert np.max(np.abs(p_interp - by_pressure["pressure"])) < 2e-5


def test_save_at_points_hit_the_value_exactly():
    values = (0.005, 0.0123, 0.0135)
    branch = trace(build_scene("balloon", nodes=51), "pressure", until={"stretch": 4.0},
                   options=ContinuationOptions(save_at=values))
    saved = branch.table[branch.table["save_at"]]
    for v in values:
        hits = saved["pressure"][np.isclose(saved["pressure"], v, rtol=1e-12, atol=0)]
        assert len(hits) >= 1
    assert len(saved) == 5                   # 0.0135 is met three times: before, between and after the folds


def test_torus_limit_point_and_fold_curve_agree_with_traces():
    Es = [0.0, 0.1538, 0.3077]
    fc = fold_curve(lambda E: build_scene("torus", nodes=60, E_hat=E, with_loads=("voltage",)), Es)
    assert fc["exists"].all() and list(fc["method"]) == ["trace", "fold", "fold"]
    assert fc["limit"].is_monotonic_decreasing                  # voltage lowers the limit pressure
    for E, limit in zip(Es[1:], fc["limit"].iloc[1:]):
        br = trace(build_scene("torus", nodes=60, E_hat=E, with_loads=("voltage",)), "pressure",
                   until={"u_max": 8.0}, options=ContinuationOptions(stop_at_first_limit=True))
        assert br.limit_points()["pressure"].iloc[0] == pytest.approx(limit, rel=1e-9)


def test_torus_aspect_ratio_fold_curve_agrees_with_trace():
    fc = fold_curve(lambda a: build_scene("torus", nodes=60, aspect_ratio=a), [0.2, 0.3, 0.4])
    br = trace(build_scene("torus", nodes=60, aspect_ratio=0.4), "pressure", until={"stretch_max": 12.0},
               options=ContinuationOptions(stop_at_first_limit=True))
    assert br.limit_points()["pressure"].iloc[0] == pytest.approx(fc["limit"].iloc[-1], rel=1e-9)
    assert fc["limit"].is_monotonic_decreasing                  # fatter tori have lower limits


def test_plate_mooney_rivlin_curve_has_no_limit_point():
    branch = trace(build_scene("plate", nodes=41), "pressure", until={"deflection": 7.5})
    assert branch.points.empty and branch.table["stable"].all()
    assert branch.table["pressure"].is_monotonic_increasing


def test_branch_file_restarts_from_a_saved_point(tmp_path):
    scene = build_scene("balloon", nodes=51)
    branch = trace(scene, "pressure", until={"stretch": 2.0})
    branch.save(tmp_path / "b.npz")
    saved = load_points(tmp_path / "b.npz")
    assert saved["q"].shape == (len(branch.table), 2 * 51) and saved["meta"]["control"] == "pressure"
    i = 5
    again = trace(scene, "pressure", until={"stretch": 2.0},
                  start=(saved["q"][i], {"pressure": float(saved["lam"][i])}))
    assert again.table["pressure"].iloc[0] == pytest.approx(branch.table["pressure"].iloc[i], rel=1e-14)
    lp_a, lp_b = branch.limit_points()["pressure"].iloc[0], again.limit_points()["pressure"].iloc[0]
    assert lp_a == pytest.approx(lp_b, rel=1e-10)


def test_rejected_steps_are_logged_with_reasons():
    branch = trace(build_scene("balloon", nodes=51), "pressure", until={"stretch": 4.0},
                   options=ContinuationOptions(ds=0.3, max_angle=0.05))
    assert len(branch.rejections) > 0
    assert branch.rejections["reason"].str.contains("tangent turned").all()
    assert list(branch.rejections.columns) == ["step", "s", "ds", "reason"]


def test_degenerate_start_follows_the_branch_the_load_drives():
    """A slack torus at rest (the shell gripper) has a null vector of K orthogonal to grad V, so
    the extended Jacobian is singular at the start and rounding alone would choose the tangent
    (it chose the null vector under LDL^T solves): the trace must go up the pressure branch."""
    scene = build_scene("gripper_shell", nodes=30, Rw=0.25)
    t = trace(scene, "volume", options=ContinuationOptions(max_steps=5)).table
    assert t["min_eig"].iloc[0] < 1e-12 * t["min_eig"].iloc[1]                 # singular at the start
    assert t["pressure"].is_monotonic_increasing and t["pressure"].iloc[-1] > 50.0
    assert (t["iterations"].iloc[1:] <= 4).all()


def test_balloon_curve_work_stays_small():
    """The benchmark's curve (N = 101, stretch 1 to 4): both limit points located on the tangent's
    pressure component with the corrector started next to the last point, the end on the stretch:
    about 130 assemblies (188 when the limit points were located on the eigenvalue)."""
    branch = trace(build_scene("balloon", nodes=101), "pressure", until={"stretch": 4.0})
    assert branch.stats["evaluations"] <= 145 and len(branch.limit_points()) == 2
    assert branch.limit_points()["located"].all() and (branch.limit_points()["min_eig"].abs() < 1e-12).all()
