"""A catalogue of stiff and extreme cases: each either succeeds, checked against a known answer,
or fails with a clear, specific message. None may hang, return NaN or report success on garbage.

Every case is a function of a small design dict returning a row: ``outcome`` ('ok' when the
case's check passed, 'failed_clearly' when the solver reported a failure with a message, 'wrong'
when it claimed success on an answer that fails the check), ``iterations``, ``step_cuts``,
``check`` (what was compared), ``error``, ``message`` and ``reason`` (empty, or the physical
reason a case's right answer is a reported failure: :func:`no_equilibrium`, whose check is that
no equilibrium is claimed where none exists).
:func:`run_case` dispatches by the design's ``case``; ``studies/stress_cases.py`` runs the whole
catalogue through :func:`snapmem.sweeps.sweep.sweep` with a per-case time limit.
"""

from __future__ import annotations

import json
import math
import time

import numpy as np

import snapmem.reference.exact as exact
from snapmem.continuation.tracer import ContinuationOptions, trace
from snapmem.errors import SnapmemError, SolverError
from snapmem.statics import equilibrium
from snapmem.catalog.scenes import build_scene


def _row(ok: bool, iterations, cuts, check, error, message) -> dict:
    bad = error is None or not math.isfinite(error)
    return {"outcome": "ok" if ok and not bad else ("wrong" if ok else "failed_clearly"),
            "iterations": int(iterations), "step_cuts": int(cuts), "check": check,
            "error": float("nan") if error is None else float(error), "message": message, "reason": ""}


def _trace_row(branch, check, error, tol):
    ok = error is not None and math.isfinite(error) and error <= tol
    message = branch.status if ok else f"{branch.status}; {check} error {error:.3g} > {tol:g}"
    return _row(ok, branch.stats["newton_iterations"], branch.stats["rejected"], check, error, message) | {
        "outcome": "ok" if ok else "wrong"}


def gent_lock(d):
    """Gent balloon inflated until the stretch reaches 99.9% of the lock stretch (I1 - 3 = Jlim).

    Check: the stretch at the final pressure against the exact uniformly inflated Gent balloon,
    p = (2 H / R) mu (lam^-1 - lam^-7) / (1 - (2 lam^2 + lam^-4 - 3) / Jlim) (pressure at fixed
    stretch would amplify the error by the curve's steepness near the lock).
    """
    Jlim = d["Jlim"]
    lam_lock = math.sqrt(max(r.real for r in np.roots([2.0, -(Jlim + 3.0), 0.0, 1.0]) if abs(r.imag) < 1e-12))
    branch = trace(build_scene("balloon", nodes=d.get("nodes", 101), material="gent", mu=1.0, Jlim=Jlim),
                   "pressure", until={"stretch": 0.999 * lam_lock})
    stretch, p = branch.table["stretch"].iloc[-1], branch.table["pressure"].iloc[-1]

    def p_exact(lam):
        return 0.02 * (1 / lam - lam ** -7) / (1 - (2 * lam ** 2 + lam ** -4 - 3) / Jlim)

    lam = np.linspace(1.0 + 1e-9, lam_lock * (1 - 1e-12), 200001)
    rising = np.flatnonzero(np.diff(p_exact(lam)) > 0)
    last_fold = lam[rising[0]] if rising.size else 1.0
    grid = lam[lam > max(last_fold, 1.0 + 1e-6)]
    grid = grid[np.concatenate([[True], np.diff(p_exact(grid)) > 0])]
    lam_exact = float(np.interp(p, p_exact(grid), grid))
    return _trace_row(branch, "stretch at the final pressure vs exact Gent balloon", abs(stretch / lam_exact - 1), 1e-3)


def thickness(d):
    """Balloon with H/R from 1e-5 to 0.1: located limit pressure against the exact formula."""
    ratio = d["H_over_R"]
    branch = trace(build_scene("balloon", nodes=101, R=1.0, H=ratio), "pressure", until={"stretch": 2.0},
                   options=ContinuationOptions(stop_at_first_limit=True))
    lps = branch.limit_points()
    if lps.empty:
        return _row(False, branch.stats["newton_iterations"], branch.stats["rejected"], "limit pressure", None,
                    f"no limit point found: {branch.status}")
    _, p_lp = exact.balloon_limit_point(R=1.0, H=ratio)
    return _trace_row(branch, "limit pressure vs exact", abs(lps["pressure"].iloc[0] / p_lp - 1), 1e-3)


def large_stretch(d):
    """Balloon traced to stretch 10: pressure along the whole curve against the exact formula."""
    branch = trace(build_scene("balloon", nodes=d.get("nodes", 201)), "pressure", until={"stretch": d["stretch"]})
    t = branch.table
    err = float(np.max(np.abs(t["pressure"] - exact.balloon_pressure(t["stretch"]))) / exact.balloon_limit_point()[1])
    reached = abs(t["stretch"].iloc[-1] - d["stretch"]) < 1e-6
    return _trace_row(branch, f"max |p - p_exact| / p_limit up to stretch {d['stretch']}",
                      err if reached else float("inf"), 2e-3)


def voltage_alone(d):
    """Balloon with no pressure, voltage raised past the electromechanical limit (E_hat max)."""
    branch = trace(build_scene("balloon", nodes=101, with_loads=("voltage",)), "E_hat", until={"stretch": 3.0})
    lps = branch.limit_points()
    lam = np.linspace(1.001, 3.0, 40001)
    e_max = float(np.nanmax(exact.balloon_e_hat(lam, 0.0)))
    if lps.empty:
        return _row(False, branch.stats["newton_iterations"], branch.stats["rejected"], "electromechanical limit", None,
                    f"no limit point: {branch.status}")
    return _trace_row(branch, "limit E_hat at p = 0 vs exact", abs(lps["E_hat"].iloc[0] / e_max - 1), 2e-3)


def mesh(d):
    """Balloon equilibrium at p_hat = 0.01 on N nodes, 5 to 100001: stretch against the exact formula."""
    n = d["nodes"]
    eq = equilibrium(build_scene("balloon", nodes=n, pressure=0.01))
    lam = exact.balloon_stretch(0.01)
    err = abs(eq.measures()["stretch"] / lam - 1) if eq.converged else None
    # the O(h^2) error is about 0.45 / N^2; past N ~ 1e4 the condition number of K (~ N^2) lets
    # double precision carry the state only to about eps N^2 ~ 1e-7
    tol = max(1.0 / n ** 2, 1e-6)
    ok = eq.converged and err is not None and err <= tol
    return _row(eq.converged, eq.report.iterations, eq.report.step_cuts, f"stretch vs exact (tol {tol:g})", err,
                eq.report.reason) | ({"outcome": "ok" if ok else ("wrong" if eq.converged else "failed_clearly")})


def fat_torus(d):
    """Torus with Rs/Rb up to 0.95: a limit point located (no exact value: must exist and be finite)."""
    branch = trace(build_scene("torus", nodes=200, aspect_ratio=d["aspect_ratio"]), "pressure",
                   until={"stretch_max": 12.0}, options=ContinuationOptions(stop_at_first_limit=True))
    lps = branch.limit_points()
    if lps.empty:
        return _row(False, branch.stats["newton_iterations"], branch.stats["rejected"], "limit point exists", None,
                    f"no limit point: {branch.status}")
    ok = bool(lps["located"].iloc[0]) and abs(lps["min_eig"].iloc[0]) < 1e-9
    return _row(True, branch.stats["newton_iterations"], branch.stats["rejected"],
                "limit point located (|min_eig| at it)", abs(lps["min_eig"].iloc[0]),
                f"p_limit = {lps['pressure'].iloc[0]:.6g}") | {"outcome": "ok" if ok else "wrong"}


#: Why :func:`no_equilibrium`'s right answer is a failure (its row's ``reason``).
NO_EQUILIBRIUM_REASON = ("physical: no equilibrium exists by design (E_hat = 1 is far past the balloon's "
                         "electromechanical limit at p_hat = 0.01); the check is that the solver says so")


def no_equilibrium(d):
    """A voltage so large no equilibrium exists (balloon at p_hat = 0.01, E_hat = 1): must fail clearly.

    Its check passes (outcome 'ok') when the solve reports no equilibrium with a message, and its
    row's ``reason`` says why that failure is the physical answer (:data:`NO_EQUILIBRIUM_REASON`).
    """
    eq = equilibrium(build_scene("balloon", nodes=81, pressure=0.01, E_hat=d["E_hat"]))
    if eq.converged:
        return _row(True, eq.report.iterations, eq.report.step_cuts, "must report no equilibrium", None,
                    f"claimed convergence: {eq.report.reason}") | {"outcome": "wrong"}
    return _row(False, eq.report.iterations, eq.report.step_cuts, "reports no equilibrium", None,
                eq.report.reason) | {"outcome": "ok", "reason": NO_EQUILIBRIUM_REASON}


def contact(d):
    """Gripper around a rod at 2000 Pa (past the free limit near 1750 Pa: the rod stops the snap),
    barrier width dhat = fraction x rod radius, down to 1e-7, and contact stiffness kappa.

    Barriers of 1e-5 of the rod and thinner switch on inside one step of the snap-through trace;
    :func:`snapmem.statics.equilibrium` then continues the barrier width down from a wider one
    (:func:`snapmem.statics.barrier_homotopy`), and the rod force converges to 273.7 N.

    The stiffest, kappa = 1e9 Pa with dhat = 4e-9 m, is ~1e13 N/m stiff at its equilibrium: its
    stiffness times the round-off of a radius (2.2e-16 x 0.04 m) is a force noise of ~6e-5 N,
    far above Newton's tolerance (5e-10 N). The residual's rounding floor counts that noise
    (snapmem.kernels.assembly.residual_floor), so the solve converges at it (failed before
    the floor counted the barriers: 'no equilibrium beyond 1729.71').
    """
    from snapmem.model.contact import contact_report
    Rw = 0.04
    scene = build_scene("gripper_rod", Rw=Rw, dhat=d["dhat_fraction"] * Rw, kappa=d["kappa"], pressure=2000.0)
    eq = equilibrium(scene)
    report = contact_report(scene, eq.q)
    gap, force = report["rod_gap"], report["rod_force"]
    ok = eq.converged and gap > 0 and math.isfinite(force) and force > 0
    return _row(eq.converged, eq.report.iterations, eq.report.step_cuts, "smallest gap > 0 and rod force > 0 (gap)",
                gap, f"{eq.report.reason}; rod force {force:.4g} N, smallest gap {gap:.3g} m") | {
        "outcome": "ok" if ok else ("wrong" if eq.converged else "failed_clearly")}


def time_step(d):
    """The pump's 30 s cycle with a fixed step dt (no adaptivity) through its snaps. Check: the snap
    time against 5 s + p_LP / (10 Pa/s), p_LP the limit pressure continuation finds for the same
    plate at 300 V (the pressure ramp crosses it there), within 0.5 s + dt."""
    from snapmem.dynamics.driver import DynamicsOptions
    from snapmem.catalog.robots import run
    nodes = 31
    branch = trace(build_scene("pump", nodes=nodes, voltage=300.0, pressure=5.0), "pressure",
                   until={"volume": 0.4}, options=ContinuationOptions(stop_at_first_limit=True, max_steps=600))
    lps = branch.limit_points()
    if lps.empty:
        return _row(False, 0, 0, "snap time", None, f"no limit point of the pump at 300 V: {branch.status}")
    t_ref = 5.0 + float(lps["pressure"].iloc[0]) / 10.0
    traj = run("pump", options=DynamicsOptions(scheme=d["scheme"], dt=d["dt"], adaptive=False, dt_max=d["dt"]),
               nodes=nodes)
    status = traj.meta.get("status", "")
    try:
        t_snap = traj.snap_time()
    except Exception as exc:                     # no snap found in the trajectory
        return _row(False, 0, 0, "snap time", None, f"{status}: {exc}")
    err = abs(t_snap - t_ref)
    completed = status == "completed"
    ok = completed and err <= 0.5 + d["dt"]
    return _row(completed, traj.meta.get("newton_iterations", 0), traj.meta.get("rejected", 0),
                "snap time vs 5 s + p_LP / (10 Pa/s) [s] (tolerance 0.5 s + dt)", err,
                f"{status}; snap at {t_snap:.3f} s, limit pressure crossed at {t_ref:.3f} s") | {
        "outcome": "ok" if ok else ("wrong" if completed else "failed_clearly")}


CASES = {
    "gent_lock": (gent_lock, [{"Jlim": j} for j in (5.0, 20.0, 270.0)]),
    "thickness": (thickness, [{"H_over_R": r} for r in (1e-5, 1e-4, 1e-3, 1e-2, 0.1)]),
    "large_stretch": (large_stretch, [{"stretch": 10.0}]),
    "voltage_alone": (voltage_alone, [{}]),
    "mesh": (mesh, [{"nodes": n} for n in (5, 11, 101, 1001, 10001, 100001)]),
    "fat_torus": (fat_torus, [{"aspect_ratio": a} for a in (0.8, 0.9, 0.95)]),
    "no_equilibrium": (no_equilibrium, [{"E_hat": 1.0}]),
    "contact": (contact, [{"dhat_fraction": f, "kappa": k} for f in (1e-1, 1e-3, 1e-5, 1e-7) for k in (1e5, 1e9)]),
    "time_step": (time_step, [{"scheme": s, "dt": dt} for s in ("euler", "bdf2") for dt in (0.01, 0.1, 0.5)]),
}


def designs(quick: bool = False) -> list[dict]:
    """Every case's designs as sweep designs {case, parameters (JSON)} (``quick``: one per case)."""
    out = []
    for name, (_, grid) in CASES.items():
        for d in (grid[:1] if quick else grid):
            out.append({"case": name, "parameters": json.dumps(d, sort_keys=True)})
    return out


def run_case(design: dict) -> dict:
    """Run one design of the catalogue (a sweep job); solver failures are rows, not exceptions."""
    name = design["case"]
    if name not in CASES:
        raise SnapmemError(f"case = {name!r}: unknown; allowed: {', '.join(CASES)}")
    params = json.loads(design["parameters"]) if isinstance(design.get("parameters"), str) else {}
    start = time.perf_counter()
    try:
        row = CASES[name][0](params)
    except SolverError as exc:
        row = _row(False, 0, 0, "", None, f"solver failure: {exc}")
    row["wall_time_s"] = time.perf_counter() - start
    return row
