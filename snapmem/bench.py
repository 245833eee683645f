"""Benchmarks: snapmem against the floor of the machine and on whole jobs, measured in one run.

Every figure is a median of repeated runs, and every comparison a ratio of two times measured in
the same run (interleaved, so that load from other processes affects both alike): never an
absolute time from another day. ``snapmem bench`` and ``studies/benchmark.py`` call :func:`run`.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import time

import numpy as np
import snapmem._lazy as _lazy

pd = _lazy.module("pandas")  # imported at first use (start-up)
from scipy.linalg.lapack import dgbsv

from snapmem.continuation import fold_curve, trace
from snapmem.catalog.scenes import build_scene

log = logging.getLogger(__name__)


def interleaved_medians(fns, min_time=0.3, min_repeats=7, max_repeats=2000):
    """Median wall time of each function, timed alternately (so load affects all alike)."""
    times = [[] for _ in fns]
    start = time.perf_counter()
    while len(times[0]) < min_repeats or (time.perf_counter() - start < min_time and len(times[0]) < max_repeats):
        for fn, ts in zip(fns, times):
            t0 = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - t0)
    return [float(np.median(ts)) for ts in times]


def newton_floor(nodes: int, scene_name: str = "balloon") -> dict:
    """One Newton iteration (assembly, factorisation, solve: as snapmem.solvers.newton does it) against
    LAPACK's band solve dgbsv of the same matrix (the floor), and against the factorisation and
    solve the iteration uses (``K.factor().solve``: the compiled LDL^T where stable) alone."""
    scene = build_scene(scene_name, nodes=nodes, pressure=0.01)
    rng = np.random.default_rng(0)
    q = scene.reference_state() * 1.2
    q[scene.free] += rng.normal(scale=1e-3, size=scene.n_free)
    loads = scene.resolve_loads(None)

    def iteration():
        ev = scene.evaluate(q, loads, order=2)
        return ev.stiffness.factor().solve(-ev.residual)

    K = scene.evaluate(q, loads).stiffness
    ab = np.array(K.ab, order="F")
    rhs = rng.normal(size=K.n)
    t_iter, t_solve, t_own = interleaved_medians([iteration, lambda: dgbsv(K.b, K.b, ab, rhs),
                                                  lambda: K.factor().solve(rhs)])
    return {"scene": scene_name, "nodes": nodes, "dofs": scene.n_free, "iteration_s": t_iter, "solve_s": t_solve,
            "own_solve_s": t_own, "factorisation": type(K.factor()).__name__, "ratio": t_iter / t_solve,
            "ratio_own": t_iter / t_own, "iteration_us_per_dof": 1e6 * t_iter / scene.n_free}


def balloon_curve(nodes: int = 101, repeats: int = 15, E_hat: float = 0.0) -> dict:
    """The whole balloon curve: stretch 1 to 4, stability at every point, limit point located.

    Returns the median and minimum wall time, the branch's counts and the located limit pressure.
    """
    scene = build_scene("balloon", nodes=nodes, E_hat=E_hat)
    trace(scene, "pressure", until={"stretch": 4.0})            # warm-up (numba cache, imports)
    times, branch = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        branch = trace(scene, "pressure", until={"stretch": 4.0})
        times.append(time.perf_counter() - t0)
    return {"median_s": float(np.median(times)), "min_s": float(np.min(times)), "points": len(branch.table),
            "steps": branch.stats["steps"], "rejected": branch.stats["rejected"],
            "newton_iterations": branch.stats["newton_iterations"], "assemblies": branch.stats["evaluations"],
            "limit_located": bool(branch.limit_points()["located"].all()),
            "p_limit": float(branch.limit_points()["pressure"].iloc[0])}


def torus_map(nodes: int = 100, ratios=np.linspace(0.05, 0.9, 18), E_hats=(0.0, 0.1538, 0.3077, 0.4615)) -> dict:
    """The torus limit-pressure map by fold continuation (one trace per E_hat, folds after)."""
    t0 = time.perf_counter()
    designs = 0
    for E in E_hats:
        table = fold_curve(lambda a: build_scene("torus", nodes=nodes, aspect_ratio=a, E_hat=E,
                                                 with_loads=("voltage",)), ratios)
        designs += int(table["exists"].sum())
    seconds = time.perf_counter() - t0
    return {"seconds": seconds, "designs": designs, "designs_per_s": designs / seconds}


def _sweep_line(args):
    """Limit pressures of tori at one thickness over aspect ratios x E_hat, by fold continuation."""
    H, ratios, E_hats, nodes = args
    rows = []

    def scene_at(a, E):
        return build_scene("torus", nodes=nodes, H=H, aspect_ratio=a, E_hat=E, with_loads=("voltage",))

    along_ratio, folds = fold_curve(lambda a: scene_at(a, E_hats[0]), ratios, return_folds=True)
    for a in ratios:
        start = folds.get(a)
        if start is None:
            rows += [{"H": H, "aspect_ratio": a, "E_hat": E, "p_limit": np.nan, "exists": False} for E in E_hats]
            continue
        along_E = fold_curve(lambda E: scene_at(a, E), E_hats, start=start) if len(E_hats) > 1 else along_ratio[
            along_ratio["value"] == a].assign(value=E_hats[0])
        for _, r in along_E.iterrows():
            rows.append({"H": H, "aspect_ratio": a, "E_hat": r["value"], "p_limit": r["limit"], "exists": r["exists"]})
    return rows


def design_sweep(n: int = 10, nodes: int = 60, workers: int | None = None) -> tuple[dict, pd.DataFrame]:
    """n^3 tori (aspect ratio x thickness x E_hat): their limit pressures, in designs per second.

    Each thickness is one task of a process pool: a trace at its first design, then Newton on the
    fold system from neighbour to neighbour across aspect ratios and, from each, across E_hat.
    """
    ratios = list(np.round(np.linspace(0.1, 0.6, n), 6))
    thicknesses = list(np.round(np.geomspace(0.05, 0.2, n), 6))
    E_hats = list(np.round(np.linspace(0.0, 0.3, n), 6))
    workers = workers or os.cpu_count() or 1
    t0 = time.perf_counter()
    tasks = [(H, ratios, E_hats, nodes) for H in thicknesses]
    with multiprocessing.get_context("fork").Pool(workers) as pool:
        rows = [r for part in pool.map(_sweep_line, tasks) for r in part]
    seconds = time.perf_counter() - t0
    table = pd.DataFrame(rows)
    return {"designs": len(table), "found": int(table["exists"].sum()), "seconds": seconds,
            "designs_per_s": len(table) / seconds, "workers": workers}, table


def robotic_real_time(scenes=("pump", "gripper_rod", "gripper_shell", "ball_drop", "ball_throw", "torus_snap"),
                      repeats: int = 3):
    """Simulated time over wall time of each robotic scene with its default settings: the median of
    ``repeats`` simulations (the scene and its start state built once before, timed as ``setup_s``:
    the ball scenes' start is a static solve of the ball resting on the balloon)."""
    from snapmem.dynamics.driver import simulate
    from snapmem.catalog.robots import experiment
    rows = []
    for name in scenes:
        t0 = time.perf_counter()
        ex = experiment(name)
        setup = time.perf_counter() - t0
        walls = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            traj = simulate(ex.scene, ex.loads, ex.t_end, rho=ex.rho, damping=ex.damping, q0=ex.q0, v0=ex.v0,
                            options=ex.options, damp_bodies=ex.damp_bodies)
            walls.append(time.perf_counter() - t0)
        wall = float(np.median(walls))
        row = {"scene": name, "t_end": ex.t_end, "wall_s": wall, "real_time_factor": ex.t_end / wall,
               "setup_s": setup, "steps": traj.meta.get("steps"),
               "newton_iterations": traj.meta.get("newton_iterations"), "status": traj.meta.get("status")}
        if name == "torus_snap":
            row["outer_radius"] = float(traj["r"][-1].max())
        rows.append(row)
    return pd.DataFrame(rows)


def run(quick: bool = False) -> pd.DataFrame:
    """Every benchmark; one row per measured figure with its target and whether it is met."""
    rows = []

    def add(item, metric, value, target=None, met=None, detail=""):
        rows.append({"item": item, "metric": metric, "value": value, "target": target, "met": met, "detail": detail})
        log.info("%s %s = %.4g", item, metric, value)

    sizes = [101, 1001] if quick else [101, 1001, 10001, 100001]
    floor = pd.DataFrame([newton_floor(n, s) for s in ("balloon", "torus") for n in sizes])
    for _, r in floor.iterrows():
        target = 5.0 if r["nodes"] <= 101 else 3.0
        add(f"newton_floor {r['scene']} N={r['nodes']}", "iteration / banded solve", r["ratio"], f"<= {target:g}",
            bool(r["ratio"] <= target), f"iteration {1e3 * r['iteration_s']:.3f} ms, LAPACK dgbsv "
            f"{1e3 * r['solve_s']:.3f} ms; its own {r['factorisation']} factor+solve {1e3 * r['own_solve_s']:.3f} ms "
            f"({r['ratio_own']:.2f}x)")
    for scene_name, sub in floor.groupby("scene"):
        big = sub[sub["nodes"] >= 1001]
        if len(big) > 1:
            def spread_of(seconds):
                per_dof = seconds / big["dofs"]
                return per_dof.max() / per_dof.min() - 1
            spread = spread_of(big["iteration_s"])
            add(f"newton_linearity {scene_name}", "per-dof time spread N >= 1001", spread, "<= 0.3", bool(spread <= 0.3),
                f"per dof over the same sizes LAPACK dgbsv alone spreads by {spread_of(big['solve_s']):.2f}, the "
                f"iteration's own factor+solve by {spread_of(big['own_solve_s']):.2f}")
    bc = balloon_curve(repeats=3 if quick else 15)
    add("balloon_curve N=101", "median seconds", bc["median_s"], "<= 0.05", bool(bc["median_s"] <= 0.05),
        f"{bc['points']} points, {bc['steps']} steps, {bc['newton_iterations']} Newton iterations")
    tm = torus_map(ratios=np.linspace(0.05, 0.9, 6 if quick else 18), E_hats=(0.0,) if quick else (0.0, 0.1538, 0.3077, 0.4615))
    add("torus_limit_map", "seconds", tm["seconds"], detail=f"{tm['designs']} limit points, {tm['designs_per_s']:.1f} /s")
    sw, _ = design_sweep(n=4 if quick else 10)
    add(f"design_sweep {sw['designs']} tori", "designs per second", sw["designs_per_s"], ">= 100",
        bool(sw["designs_per_s"] >= 100), f"{sw['found']} limit points in {sw['seconds']:.1f} s on {sw['workers']} workers")
    if not quick:
        robots = robotic_real_time()
        for _, r in robots.iterrows():
            target = 100.0
            add(f"robot {r['scene']}", "real-time factor", r["real_time_factor"], f">= {target:g}",
                bool(r["real_time_factor"] >= target), f"{r['wall_s']:.3f} s wall (median of 3; setup "
                f"{r['setup_s']:.3f} s), {r['steps']} steps, status {r['status']}")
            if r["scene"] == "torus_snap":
                add("torus_snap", "wall seconds", r["wall_s"], "<= 0.25", bool(r["wall_s"] <= 0.25),
                    f"{r['newton_iterations']} Newton iterations, outer radius {r['outer_radius']:.4g}")
    return pd.DataFrame(rows)
