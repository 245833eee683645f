"""Paper Fig. 3 (d-f): the hyperelastic plate, balloon and torus, traced by continuation.

The Mooney-Rivlin plate rises monotonically (no limit point: MODEL.md); the balloon lies on the
exact formula through its limit point and pressure minimum; the torus passes a limit point.
Writes fig3_plate.csv, fig3_balloon.csv, fig3_torus.csv and one PNG each.
"""

import numpy as np

from snapmem import build_scene, exact
from snapmem.viz.plotting import plot_branch
from snapmem.study import parse_args, save


def main(argv=None):
    args = parse_args(__doc__, argv)
    nodes = 41 if args.quick else 201
    cases = {
        "plate": ("deflection", 7.5, dict(R=7.5), {"deflection": 7.5}),
        "balloon": ("stretch", None, dict(), {"stretch": 4.0}),
        "torus": ("u_max", 10.0, dict(), {"u_max": 10.0}),
    }
    from snapmem.continuation.tracer import trace
    out = {}
    for name, (x, length, params, until) in cases.items():
        branch = trace(build_scene(name, nodes=nodes, **params), "pressure", until=until)
        table = branch.table.copy()
        if length is not None:
            table[f"{x}_normalised"] = table[x] / length
        save(args, f"fig3_{name}", table, scene=name, nodes=nodes, until=until, status=branch.status)
        xs = f"{x}_normalised" if length is not None else x
        lam = np.linspace(1, 4, 300)
        plot_branch(table, xs, "pressure", path=args.out / f"fig3_{name}.png", label="snapmem",
                    exact=(lam, exact.balloon_pressure(lam)) if name == "balloon" else None,
                    title=f"Fig. 3: {name}, N = {nodes}")
        out[name] = table
    return out


if __name__ == "__main__":
    main()
