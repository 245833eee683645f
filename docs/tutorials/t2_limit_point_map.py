"""Tutorial 2: a limit-point map.

How does a voltage lower the balloon's limit pressure? :func:`snapmem.continuation.fold_curve`
follows the limit point itself as a second parameter (here E_hat, the normalised electric field)
varies: the first LP comes from a traced branch, every next one from a few Newton steps on the
extended system R = 0, det K = 0 (a fold curve), so the map costs little more than one trace.
The exact thin-sphere limit pressure of docs/MODEL.md is drawn beside it.

    python docs/tutorials/t2_limit_point_map.py [--quick]
"""

import numpy as np

from snapmem import build_scene
from snapmem.continuation import fold_curve
from snapmem.reference import exact

from _common import parse


def main(argv=None):
    args = parse(__doc__, argv)
    nodes = 41 if args.quick else 201
    e_hats = np.linspace(0.0, 0.3, 4 if args.quick else 13)
    table = fold_curve(lambda e: build_scene("balloon", nodes=nodes, E_hat=e, with_loads=("voltage",)), e_hats,
                       "pressure")
    table["p_limit_exact"] = [exact.balloon_limit_point(E_hat=e)[1] for e in table["value"]]
    table.to_csv(args.out / "balloon_limit_map.csv", index=False)
    for _, row in table.iterrows():
        print(f"E_hat = {row['value']:.3f}: p_hat at the limit = {row['limit']:.6g} "
              f"(exact {row['p_limit_exact']:.6g}, {row['method']})")
    return table


if __name__ == "__main__":
    main()
