"""Limit-point maps of the torus (paper Fig. 5 c, d, extended), by fold-curve continuation.

Limit pressure against aspect ratio Rs/Rb (0.05 to 0.9) for E_hat in {0, 0.1538, 0.3077, 0.4615},
and limit E_hat against aspect ratio for p_hat in {0.0260, 0.0284, 0.0710, 0.0947}. A row with
exists = False marks a design with no limit point on the branch loaded from rest (for the voltage
map: a pressure above the unactuated limit pressure, so the torus has already snapped). A few
points are checked against limit points of traced branches (columns p_limit_traced).
Writes results/torus_limit_pressure_map.csv and results/torus_limit_voltage_map.csv.
"""

import numpy as np
import pandas as pd

from snapmem import build_scene
from snapmem.continuation import ContinuationOptions, fold_curve, trace
from snapmem.plotting import plot_xy
from snapmem.study import parse_args, save


def limit_map(nodes, ratios, loads, control, fixed_name):
    tables = []
    for value in loads:
        params = {fixed_name: value}
        curve = fold_curve(lambda a: build_scene("torus", nodes=nodes, aspect_ratio=a, with_loads=("voltage",),
                                                 **params), ratios, control)
        curve.insert(0, fixed_name, value)
        tables.append(curve)
    return pd.concat(tables, ignore_index=True)


def traced_limit(nodes, ratio, control, **params):
    branch = trace(build_scene("torus", nodes=nodes, aspect_ratio=ratio, with_loads=("voltage",), **params),
                   control, until={"stretch_max": 12.0}, options=ContinuationOptions(stop_at_first_limit=True))
    lps = branch.limit_points()
    return float(lps["control"].iloc[0]) if len(lps) else float("nan")


def main(argv=None):
    args = parse_args(__doc__, argv)
    nodes = 40 if args.quick else 100
    ratios = np.round(np.linspace(0.05, 0.9, 6 if args.quick else 18), 4)
    pm = limit_map(nodes, ratios, [0.0, 0.1538, 0.3077, 0.4615], "pressure", "E_hat")
    pm = pm.rename(columns={"value": "aspect_ratio", "limit": "p_limit", "u_max": "u_max_limit"})
    checks = [(0.0, ratios[1]), (0.3077, ratios[-2])]
    pm["p_limit_traced"] = np.nan
    for E, a in checks:
        pm.loc[(pm["E_hat"] == E) & (pm["aspect_ratio"] == a), "p_limit_traced"] = traced_limit(nodes, a, "pressure", E_hat=E)
    cols = ["aspect_ratio", "E_hat", "p_limit", "u_max_limit", "exists", "method", "iterations", "p_limit_traced"]
    save(args, "torus_limit_pressure_map", pm[cols + [c for c in pm.columns if c not in cols]], nodes=nodes)
    plot_xy(pm[pm["exists"]], "aspect_ratio", "p_limit", args.out / "torus_limit_pressure_map.png", group="E_hat",
            title="Torus limit pressure against Rs/Rb (Fig. 5c)")

    vm = limit_map(nodes, ratios, [0.0260, 0.0284, 0.0710, 0.0947], "E_hat", "pressure")
    vm = vm.rename(columns={"value": "aspect_ratio", "limit": "E_hat_limit", "u_max": "u_max_limit"})
    vm = vm.drop(columns=["E_hat"]).rename(columns={"pressure": "pressure"})
    vm["E_hat_limit_traced"] = np.nan
    p, a = 0.0260, ratios[2]
    vm.loc[(vm["pressure"] == p) & (vm["aspect_ratio"] == a), "E_hat_limit_traced"] = traced_limit(nodes, a, "E_hat", pressure=p)
    cols = ["aspect_ratio", "pressure", "E_hat_limit", "u_max_limit", "exists", "method", "iterations", "E_hat_limit_traced"]
    save(args, "torus_limit_voltage_map", vm[cols + [c for c in vm.columns if c not in cols]], nodes=nodes)
    plot_xy(vm[vm["exists"]], "aspect_ratio", "E_hat_limit", args.out / "torus_limit_voltage_map.png", group="pressure",
            title="Torus limit E_hat against Rs/Rb (Fig. 5d)")
    return pm, vm


if __name__ == "__main__":
    main()
