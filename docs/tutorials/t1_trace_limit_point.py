"""Tutorial 1: trace a branch and read its limit point.

A Mooney-Rivlin balloon (R = 10 m, H = 0.1 m) inflated by pressure: the pressure rises with the
stretch, reaches a maximum (the limit point LP, where the balloon snaps under pressure control),
then falls. Continuation in the pressure follows the curve through the LP; the LP is located
(not only bracketed) and its stretch and pressure agree with the exact thin-sphere curve of
docs/MODEL.md.

    python docs/tutorials/t1_trace_limit_point.py [--quick]
"""

from snapmem import build_scene
from snapmem.continuation import trace
from snapmem.reference import exact

from _common import parse


def main(argv=None):
    args = parse(__doc__, argv)
    scene = build_scene("balloon", nodes=41 if args.quick else 201)
    branch = trace(scene, "pressure", until={"stretch_max": 3.0})
    branch.table.to_csv(args.out / "balloon_branch.csv", index=False)
    lp = branch.limit_points().iloc[0]           # one row of branch.points: kind, control, stretch_max, located, ...
    lam_exact, p_exact = exact.balloon_limit_point()
    print(f"limit point: p_hat = {lp['control']:.6g} (exact {p_exact:.6g}), "
          f"stretch = {lp['stretch_max']:.5g} (exact {lam_exact:.5g}), located = {lp['located']}")
    print(f"branch: {len(branch.table)} points, status {branch.status}; stable part: "
          f"{int(branch.table['stable'].sum())} points")
    return lp, (lam_exact, p_exact)


if __name__ == "__main__":
    main()
