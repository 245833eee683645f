"""The robotic figures' data (paper Figs 6-8): pump pressure-volume curves, gripper contact force
against pressure, ball heights in time, at rest, and when thrown. One CSV (+ JSON sidecar) each.

    python studies/robot_curves.py [--quick] [--only pump gripper ball] [--out results/robots]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from snapmem import build_scene
from snapmem.continuation.tracer import ContinuationOptions, trace
from snapmem.io.results import write_table
from snapmem.catalog.robots import events, resting, run


def pump(out, nodes, quick):
    rows, limits = [], []
    for phi in ((0.0, 300.0) if quick else (0.0, 100.0, 200.0, 300.0)):
        scene = build_scene("pump", nodes=nodes, voltage=phi, pressure=5.0)   # 300 V at p = 0 is slack
        branch = trace(scene, "pressure", until={"volume": 0.4}, options=ContinuationOptions(max_steps=600))
        rows.append(branch.table.assign(phi=phi))
        for _, lp in branch.points.iterrows():
            limits.append({"phi": phi, "kind": lp["kind"], "pressure": lp["control"], "volume": lp["volume"]})
    write_table(pd.concat(rows), out / "pump_pv.csv", {"study": "pump p-V", "nodes": nodes})
    write_table(pd.DataFrame(limits), out / "pump_limits.csv", {"study": "pump limit points", "nodes": nodes})
    return pd.DataFrame(limits)


def gripper(out, nodes, quick):
    cases = [("gripper_rod", rw, 0.0) for rw in (0.04, 0.05, 0.06, 0.07)]
    cases += [("gripper_rod", 0.04, phi) for phi in (1000.0, 1500.0)]
    cases += [("gripper_shell", rw, 0.0) for rw in (0.13, 0.17, 0.21, 0.25)]
    cases += [("gripper_shell", 0.25, phi) for phi in (1000.0, 1500.0)]
    if quick:
        cases = [cases[3], cases[-3]]
    rows, summary = [], []
    for name, rw, phi in cases:
        scene = build_scene(name, nodes=nodes, Rw=rw, voltage=phi)
        # shells: volume control passes the free torus's pressure maximum without a jump (pressure
        # control stalls past it there); rods: pressure control (under volume control the outer
        # side balloons and the steps become tiny)
        control = "pressure" if name == "gripper_rod" else "volume"
        branch = trace(scene, control, until={"pressure": 2500.0}, options=ContinuationOptions(max_steps=800))
        key = "rod_force" if name == "gripper_rod" else "shell_force"
        table = branch.table.assign(scene=name, Rw=rw, phi=phi, force=branch.table[key])
        rows.append(table[["scene", "Rw", "phi", "pressure", "force", "stable", "min_tension", "volume"]])
        touch = table[table["force"] > 0]
        free = table if touch.empty else table.loc[: touch.index[0]]
        summary.append({"scene": name, "Rw": rw, "phi": phi,
                        "free_limit_pressure": float(free["pressure"].max()) if free["pressure"].idxmax() < free.index[-1] else np.nan,
                        "contact_from_pressure": float(touch["pressure"].iloc[0]) if len(touch) else np.nan,
                        "force_at_end": float(table["force"].iloc[-1]), "pressure_at_end": float(table["pressure"].iloc[-1]),
                        "status": branch.status})
    write_table(pd.concat(rows), out / "gripper_force.csv", {"study": "gripper force", "nodes": nodes})
    write_table(pd.DataFrame(summary), out / "gripper_summary.csv", {"study": "gripper", "nodes": nodes})
    return pd.DataFrame(summary)


def ball(out, nodes, quick):
    """Ball tables: ``ball_z`` is the centre's height above the balloon's centre, ``height`` (the
    paper's b_h) and ``ball_apex`` above the plate it stands on, R = 0.1 m lower [m]."""
    drops, rest, throws = [], [], []
    R = 0.1
    for xi in ((10.0,) if quick else (0.1, 1.0, 10.0)):
        traj = run("ball_drop", nodes=nodes, xi=xi, t_end=0.5 if quick else 60.0)
        drops.append(pd.DataFrame({"xi": xi, "t": traj["t"], "ball_z": traj["ball_z"], "min_gap": traj["min_gap"],
                                   "height": traj["ball_z"] + R}))
    static = resting(build_scene("ball_drop", nodes=nodes), 500.0)[-1]
    for mb in ((0.5,) if quick else (0.1, 0.3, 0.5)):
        for p in ((450.0, 500.0) if quick else np.arange(300.0, 575.0, 25.0)):
            q = resting(build_scene("ball_drop", nodes=nodes, mb=mb, pressure=p), p)
            rest.append({"mb": mb, "pressure": p, "ball_z": q[-1], "height": q[-1] + R})
    for phi in ((0.0,) if quick else (0.0, 200.0, 400.0, 600.0)):
        traj = run("ball_throw", nodes=nodes, voltage=phi, t_end=0.5 if quick else 3.0)
        throws.append({"phi": phi, **events(traj), "min_gap": float(traj["min_gap"].min())})   # ball_apex: above the plate
    write_table(pd.concat(drops), out / "ball_drop.csv", {"study": "ball drop", "nodes": nodes,
                                                           "static_height_500Pa_0.5kg": float(static)})
    write_table(pd.DataFrame(rest), out / "ball_rest.csv", {"study": "ball at rest", "nodes": nodes})
    write_table(pd.DataFrame(throws), out / "ball_throw.csv", {"study": "ball throw", "nodes": nodes})
    finals = pd.concat(drops).groupby("xi")["ball_z"].last()
    return pd.DataFrame(throws), finals, float(static), pd.DataFrame(rest)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="coarse meshes, few cases, short runs")
    parser.add_argument("--only", nargs="*", default=["pump", "gripper", "ball"])
    parser.add_argument("--out", default="results/robots")
    args = parser.parse_args(argv)
    out = Path(args.out)
    results = {}
    with pd.option_context("display.width", 200, "display.float_format", "{:.5g}".format):
        if "pump" in args.only:
            results["pump"] = pump(out, 21 if args.quick else 61, args.quick)
            print(results["pump"].to_string(index=False))
        if "gripper" in args.only:
            results["gripper"] = gripper(out, 30 if args.quick else 80, args.quick)
            print(results["gripper"].to_string(index=False))
        if "ball" in args.only:
            results["ball"] = ball(out, 21 if args.quick else 61, args.quick)
            throws, finals, static, rest = results["ball"]
            print(throws.to_string(index=False))
            print("ball_drop final heights by xi:", finals.to_dict(), "static:", static)
            print(rest.pivot(index="pressure", columns="mb", values="ball_z").to_string())
    return results


if __name__ == "__main__":
    main()
