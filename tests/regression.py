"""Fingerprints of representative runs, to prove that a refactor changes no number.

It imports the flat module paths of snapmem 0.1, so the same script runs on the code before the
layered split and after it (where those paths are aliases).

``python tests/regression.py --write`` records them in tests/data/regression.json; the test
``tests/test_regression.py`` recomputes them and requires iteration and step counts to be equal and
every recorded value to agree to 1e-9 relative (frames and iterates; the refactors reorder no
floating-point operation knowingly, and this bound still catches any changed formula).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

DATA = Path(__file__).parent / "data" / "regression.json"


def _trace(scene_name, control, until, **params):
    from snapmem.scenes import build_scene
    from snapmem.continuation import trace
    with_loads = ("voltage",) if control in ("voltage", "E_hat") else ()
    branch = trace(build_scene(scene_name, with_loads, **params), control, until=until)
    t = branch.table
    out = {"points": len(t), "newton": int(branch.stats["newton_iterations"]), "status": str(branch.status),
           "kinds": [str(k) for k in branch.points["kind"]],
           "critical": [float(v) for v in branch.points[control]] if len(branch.points) else [],
           "last_x": [float(np.linalg.norm(branch.states[-1].x)), float(branch.states[-1].lam)]}
    for col in ("stretch_max", "u_max", "min_eig", "volume"):
        out[col] = [float(t[col].iloc[i]) for i in (1, len(t) // 2, -1)]
    return out


def _simulate(name, t_end):
    from snapmem.robots import run
    traj = run(name, t_end=t_end)
    d = traj.data
    return {"frames": int(len(d["t"])), "steps": int(traj.meta.get("steps", -1)),
            "newton": int(np.sum(d["newton"])),
            "q_final": float(np.linalg.norm(d["q"][-1])), "volume": [float(d["volume"][i]) for i in (1, -1)],
            "total": float(d["total"][-1])}


def _equilibrium(scene_name, loads, **params):
    from snapmem.scenes import build_scene
    from snapmem.statics import equilibrium
    eq = equilibrium(build_scene(scene_name, **params), loads)
    return {"converged": bool(eq.converged), "iterations": int(eq.report.iterations), "reason": eq.report.reason,
            "q": float(np.linalg.norm(eq.q))}


CASES = {
    "trace_balloon": lambda: _trace("balloon", "pressure", {"stretch": 4.0}, nodes=41),
    "trace_balloon_E": lambda: _trace("balloon", "pressure", {"stretch": 3.2}, nodes=41, E_hat=0.4),
    "trace_plate_voltage": lambda: _trace("plate", "voltage", {"voltage": 1.5}, nodes=31, pressure=0.01),
    "trace_torus": lambda: _trace("torus", "pressure", {"u_max": 4.0}, nodes=40),
    "trace_balloon_volume": lambda: _trace("balloon", "volume", {"stretch": 3.0}, nodes=31),
    "equilibrium_snap": lambda: _equilibrium("balloon", {"pressure": 0.0141}, nodes=41),
    "sim_pump": lambda: _simulate("pump", 10.0),
    "sim_gripper_rod": lambda: _simulate("gripper_rod", None),
    "sim_ball_drop": lambda: _simulate("ball_drop", 0.3),
    "sim_ball_throw": lambda: _simulate("ball_throw", None),
    "sim_torus_snap": lambda: _simulate("torus_snap", None),
}


def compute(names=None) -> dict:
    return {name: CASES[name]() for name in (names or CASES)}


#: Absolute floors of quantities that can be zero up to rounding: the table's smallest eigenvalue
#: in a row that lands on a critical point (trace_balloon_E's middle row, 3e-16 against 1e-2
#: elsewhere) takes the rounding of the BLAS kernels the machine picks (OPENBLAS_CORETYPE), which
#: no relative tolerance covers.
ABSOLUTE = {"min_eig": 1e-12}


def compare(expected, actual, where="", rtol=1e-9, atol=0.0) -> list[str]:
    """Differences between two fingerprints (empty when they agree): floats within ``rtol``
    relative or ``atol`` absolute (:data:`ABSOLUTE` by key), everything else equal."""
    if isinstance(expected, dict):
        return [d for k in expected for d in compare(expected[k], actual.get(k), f"{where}.{k}", rtol,
                                                     ABSOLUTE.get(k, atol))]
    if isinstance(expected, list):
        if not isinstance(actual, list) or len(actual) != len(expected):
            return [f"{where}: {actual!r} != {expected!r}"]
        return [d for i, (e, a) in enumerate(zip(expected, actual))
                for d in compare(e, a, f"{where}[{i}]", rtol, atol)]
    if isinstance(expected, float) and isinstance(actual, float):
        ok = ((np.isnan(expected) and np.isnan(actual))
              or abs(actual - expected) <= max(rtol * max(abs(expected), 1e-300), atol))
        return [] if ok else [f"{where}: {actual!r} != {expected!r}"]
    return [] if actual == expected else [f"{where}: {actual!r} != {expected!r}"]


if __name__ == "__main__":
    if "--write" in sys.argv:
        DATA.write_text(json.dumps(compute(), indent=1) + "\n")
        print(f"wrote {DATA}")
    else:
        diffs = compare(json.loads(DATA.read_text()), compute())
        print("\n".join(diffs) or "identical")
