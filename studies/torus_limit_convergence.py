"""Mesh convergence of the torus limit pressure (Rb = 10, Rs = 2, H = 0.1, MR c1/c2 = 7, E_hat = 0).

For N = 51, 101, 201, 401, 801 nodes, the located limit pressure, its change from the previous
mesh and the observed order log2(|p_N - p_N/2| / |p_2N - p_N|); also the Richardson estimate of
the converged value from the two finest meshes (order 2). Writes torus_limit_convergence.csv.
"""

import numpy as np
import pandas as pd

from snapmem import build_scene
from snapmem.continuation.tracer import ContinuationOptions, trace
from snapmem.viz.plotting import plot_xy
from snapmem.study import parse_args, save


def limit_pressure(nodes):
    branch = trace(build_scene("torus", nodes=nodes), "pressure", until={"u_max": 10.0},
                   options=ContinuationOptions(stop_at_first_limit=True))
    return branch.limit_points().iloc[0]


def main(argv=None):
    args = parse_args(__doc__, argv)
    sizes = [26, 51, 101, 201] if args.quick else [51, 101, 201, 401, 801]
    rows = [{"nodes": n, "p_limit": float(lp["pressure"]), "u_max_limit": float(lp["u_max"])}
            for n, lp in ((n, limit_pressure(n)) for n in sizes)]
    t = pd.DataFrame(rows)
    t["change"] = t["p_limit"].diff()
    t["observed_order"] = np.log2(t["change"].shift(1).abs() / t["change"].abs())
    p_inf = t["p_limit"].iloc[-1] + (t["p_limit"].iloc[-1] - t["p_limit"].iloc[-2]) / 3.0
    t["error_vs_richardson"] = (t["p_limit"] - p_inf).abs() / p_inf
    save(args, "torus_limit_convergence", t, richardson_p_limit=p_inf)
    plot_xy(t, "nodes", "error_vs_richardson", args.out / "torus_limit_convergence.png", logx=True, logy=True,
            title="Torus limit pressure: mesh convergence")
    print(t.to_string(index=False))
    return t


if __name__ == "__main__":
    main()
