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

from snapmem import SolverError, build_scene
from snapmem.continuation import ContinuationOptions, fold_curve, trace
from snapmem.viz.plotting import plot_xy
from snapmem.study import parse_args, save


def limit_map(nodes, ratios, loads, control, fixed_name):
    tables = []
    for value in loads:
        params = {fixed_name: value}
        curve = fold_curve(lambda a: build_scene("torus", nodes=nodes, aspect_ratio=a, with_loads=("voltage",),
                                                 **params), ratios, control)
        curve = curve.drop(columns=[fixed_name], errors="ignore")   # the measured copy: NaN where no fold
        curve.insert(0, fixed_name, value)
        tables.append(curve)
    return pd.concat(tables, ignore_index=True)


def traced_limit(nodes, ratio, control, **params):
    """The first limit point of a branch traced from rest (NaN if there is none)."""
    try:
        branch = trace(build_scene("torus", nodes=nodes, aspect_ratio=ratio, with_loads=("voltage",), **params),
                       control, until={"stretch_max": 12.0}, options=ContinuationOptions(stop_at_first_limit=True))
    except SolverError:
        return float("nan")
    lps = branch.limit_points()
    return float(lps["control"].iloc[0]) if len(lps) else float("nan")


def check_against_traces(table, fixed, limit, nodes, control, count=2):
    """Fill ``<limit>_traced`` for a few designs whose limit came from the fold curve."""
    table[f"{limit}_traced"] = np.nan
    folds = table[table["exists"] & (table["method"] == "fold")]
    for i in folds.index[np.linspace(0, len(folds) - 1, min(count, len(folds))).astype(int)] if len(folds) else []:
        row = table.loc[i]
        table.loc[i, f"{limit}_traced"] = traced_limit(nodes, row["aspect_ratio"], control, **{fixed: row[fixed]})


def main(argv=None):
    args = parse_args(__doc__, argv)
    nodes = 40 if args.quick else 100
    ratios = np.round(np.linspace(0.05, 0.9, 4 if args.quick else 18), 4)
    pm = limit_map(nodes, ratios, [0.0, 0.3077] if args.quick else [0.0, 0.1538, 0.3077, 0.4615], "pressure", "E_hat")
    pm = pm.rename(columns={"value": "aspect_ratio", "limit": "p_limit", "u_max": "u_max_limit"})
    check_against_traces(pm, "E_hat", "p_limit", nodes, "pressure")
    cols = ["aspect_ratio", "E_hat", "p_limit", "u_max_limit", "exists", "method", "iterations", "p_limit_traced"]
    save(args, "torus_limit_pressure_map", pm[cols + [c for c in pm.columns if c not in cols]], nodes=nodes)
    plot_xy(pm[pm["exists"]], "aspect_ratio", "p_limit", args.out / "torus_limit_pressure_map.png", group="E_hat",
            title="Fig. 5c: torus limit pressure")

    vm = limit_map(nodes, ratios, [0.0260, 0.0710] if args.quick else [0.0260, 0.0284, 0.0710, 0.0947], "E_hat", "pressure")
    vm = vm.rename(columns={"value": "aspect_ratio", "limit": "E_hat_limit", "u_max": "u_max_limit"})
    vm = vm.drop(columns=["E_hat"], errors="ignore")
    check_against_traces(vm, "pressure", "E_hat_limit", nodes, "E_hat")
    cols = ["aspect_ratio", "pressure", "E_hat_limit", "u_max_limit", "exists", "method", "iterations", "E_hat_limit_traced"]
    save(args, "torus_limit_voltage_map", vm[cols + [c for c in vm.columns if c not in cols]], nodes=nodes)
    plot_xy(vm[vm["exists"]], "aspect_ratio", "E_hat_limit", args.out / "torus_limit_voltage_map.png", group="pressure",
            title="Fig. 5d: torus limit field")
    return pm, vm


if __name__ == "__main__":
    main()
