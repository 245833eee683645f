"""The two-balloon experiment under total-volume control against the exact pair.

Two identical Mooney-Rivlin balloons (the MODEL.md validation balloon, R = 10, H = 0.1, mu = 1)
share one chamber of prescribed fluid volume V (``two_balloons``, ``--control volume``). The
symmetric branch loses stability at the two BPs where one balloon's dp/dV = 0; switching at each
BP gives the asymmetric branch (one balloon shrinks, the other grows; the two halves are the
mirror images), traced to its fold in V, where p_1'(V_1) + p_2'(V_2) = 0 and its stability
changes. An unequal pair (R2 = 10.2, an imperfection) is drawn beside it: its branches do not
cross. The exact curves (snapmem.reference.two_balloons) are drawn under the computed ones.

Writes two_balloons.csv (the BPs' and the fold's V and p at N = 51, 101, 201 against the exact
values: relative error and observed order, expected 2), two_balloons.branches.csv (the branches at
N = 101) and two_balloons.png. ``--speed`` times the must-show run instead (:func:`timed_pair`:
the symmetric branch through both BPs and the asymmetric half to its fold at N = 101, median of 5
warm runs in-process) and writes two_balloons.speed.csv.
"""


import os
import statistics
import time

import numpy as np
import pandas as pd
from scipy.optimize import brentq

#: ``--speed`` times compiled kernels: one not in numba's cache yet (after a change) compiles at its
#: first call instead of running as Python (snapmem._lazy's first-use policy).
os.environ.setdefault("SNAPMEM_COLD", "compile")

from snapmem import build_scene
from snapmem.continuation import ContinuationOptions, trace
from snapmem.continuation.switching import switch_at
from snapmem.reference.exact import balloon_extrema, balloon_pressure
from snapmem.reference.two_balloons import asymmetric_fold, balloon_volume, symmetric_bifurcations
from snapmem.study import parse_args, save
from snapmem.viz import style

STRETCH_LIMIT = 4.0                   # where the symmetric and the imperfect branches stop
IMPERFECT_R2 = 10.2                   # the unequal pair's second radius [m]


def pair_branches(nodes: int, R2: float = 10.0) -> dict:
    """{'symmetric': Branch, 'asymmetric BP1 +': Branch, ...} of the pair at ``nodes``: the branch
    from the reference state, and for an identical pair both halves switched at each BP, each
    traced to the fold of V."""
    scene = build_scene("two_balloons", nodes=nodes, R2=R2)
    # the generic 3 corrector iterations aimed at: these branches are drawn, and denser points draw them smoothly
    main = trace(scene, "volume", until={"stretch_max": STRETCH_LIMIT},
                 options=ContinuationOptions(max_steps=400, target_iterations=3))
    out = {"symmetric" if R2 == 10.0 else f"R2 = {R2:g}": main}
    if R2 != 10.0:
        return out
    for k in range(len(main.points)):
        halves = switch_at(scene, "volume", main.critical_state(k),
                           options=ContinuationOptions(stop_at_first_limit=True, max_steps=300, target_iterations=3))
        for direction, child in halves:
            out[f"asymmetric BP{k + 1} {'+' if direction > 0 else '-'}"] = child
    return out


#: The generic options, for comparison: the corrector aims at 3 Newton iterations and runs a
#: diverging corrector to its iteration limit (the defaults of a scene without continuation
#: defaults). ``two_balloons`` aims at 5 by default (its ``continuation_defaults``,
#: snapmem.catalog.chambers), so the step grows on the smooth stretches between critical points
#: (about half as many points), and cuts a step as soon as its corrector diverges. The points located on the way (BPs, fold,
#: the end) do not depend on the steps: they are the generic trace's to 1e-11 relative
#: (tests/test_chambers.py).
GENERIC = ContinuationOptions(target_iterations=3, abandon_diverging=False)


def timed_pair(nodes: int = 101, options: ContinuationOptions = ContinuationOptions()) -> tuple:
    """(the symmetric branch to stretch_max 2.8, through both BPs; the asymmetric half switched at
    the first BP, to its fold) of two identical balloons at ``nodes``: the must-show run."""
    scene = build_scene("two_balloons", nodes=nodes)
    main = trace(scene, "volume", until={"stretch_max": 2.8}, options=options)
    switched = ContinuationOptions(**{**options.__dict__, "stop_at_first_limit": True, "max_steps": 200})
    (_, half), *_ = switch_at(scene, "volume", main.critical_state(0), options=switched)
    return main, half


def speed(nodes: int = 101, repeats: int = 5) -> pd.DataFrame:
    """Median wall and CPU time [s] of :func:`timed_pair` over ``repeats`` warm runs, with the
    default options (the scene's: 5 corrector iterations aimed at) and with :data:`GENERIC` (3),
    alternated run by run (a loaded machine slows both alike), and each run's points and Newton
    iterations."""
    rows = []
    runs = {"default": ContinuationOptions(), "target_3": GENERIC}
    traced = {name: timed_pair(nodes, options) for name, options in runs.items()}   # warm: kernels, caches
    wall = {name: [] for name in runs}
    cpu = {name: [] for name in runs}
    for _ in range(repeats):
        for name, options in runs.items():
            t0, c0 = time.perf_counter(), time.process_time()
            timed_pair(nodes, options)
            wall[name].append(time.perf_counter() - t0)
            cpu[name].append(time.process_time() - c0)
    for name, (main, half) in traced.items():
        rows.append({"options": name, "nodes": nodes, "wall_s": statistics.median(wall[name]),
                     "cpu_s": statistics.median(cpu[name]), "points": len(main.table) + len(half.table),
                     "newton": main.stats["newton_iterations"] + half.stats["newton_iterations"],
                     "bp1_volume": main.points["control"].iloc[0], "bp2_volume": main.points["control"].iloc[1],
                     "fold_volume": half.limit_points()["control"].iloc[0]})
    return pd.DataFrame(rows)


def errors(sizes) -> pd.DataFrame:
    """The BPs' and the asymmetric fold's V and p at each N against the exact pair."""
    bps = symmetric_bifurcations()
    fold = asymmetric_fold()
    rows = []
    for n in sizes:
        branches = pair_branches(n)
        points = branches["symmetric"].points
        fold_row = branches["asymmetric BP1 +"].limit_points().iloc[0]
        for k in range(2):
            rows.append(("BP%d" % (k + 1), n, points["control"].iloc[k], points["pressure"].iloc[k],
                         bps[k][0], bps[k][1]))
        rows.append(("fold", n, fold_row["control"], fold_row["pressure"], fold[0], fold[1]))
    t = pd.DataFrame(rows, columns=["point", "nodes", "volume", "pressure", "exact_volume", "exact_pressure"])
    t["volume_error"] = (t["volume"] / t["exact_volume"] - 1).abs()
    t["pressure_error"] = (t["pressure"] / t["exact_pressure"] - 1).abs()
    for q in ("volume", "pressure"):
        t[f"{q}_order"] = t.groupby("point")[f"{q}_error"].transform(
            lambda e: np.log(e.shift(1) / e) / np.log(2.0))      # N - 1 doubles from row to row
    return t


def exact_curves():
    """(symmetric, asymmetric) exact curves as (V, p) arrays: V = 2 V(lam) along p(lam), and the
    pairs p(lam_1) = p(lam_2) over the three roots of p(lam) = p in (p_min, p_max)."""
    lam = np.linspace(1.0, STRETCH_LIMIT, 600)
    symmetric = (2 * balloon_volume(lam), balloon_pressure(lam))
    (l_max, p_max), (l_min, p_min) = balloon_extrema()[:2]
    ps = np.linspace(p_min, p_max, 400)[1:-1]
    hi = l_min * 3
    roots = np.array([[brentq(lambda x: balloon_pressure(x) - p, a, b, xtol=1e-14)
                       for a, b in ((1.0, l_max), (l_max, l_min), (l_min, hi))] for p in ps])
    volume = balloon_volume(roots)
    pairs = [(volume[:, 0] + volume[:, 1], ps), (volume[:, 0] + volume[:, 2], ps), (volume[:, 1] + volume[:, 2], ps)]
    return symmetric, pairs


def branch_table(branches: dict) -> pd.DataFrame:
    columns = ["s", "control", "pressure", "volume_1", "volume_2", "stretch_1", "stretch_2", "negative_eigs",
               "stable", "point"]
    tables = []
    for name, b in branches.items():
        t = b.table[columns].copy()
        t.insert(0, "branch", name)
        tables.append(t)
    return pd.concat(tables, ignore_index=True)


def draw(t: pd.DataFrame, path) -> None:
    """Left: p against V (stable solid, unstable dashed; exact curves in grey). Right: each
    balloon's stretch against V, where the symmetry breaking shows."""
    fig, (left, right) = style.axes(ncols=2)
    symmetric, pairs = exact_curves()
    for ax in (left, right):
        ax.set_xlabel(r"total volume $V$")
    left.plot(*symmetric, color="0.75", lw=3.5, label="exact pair")
    for v, p in pairs:
        left.plot(v, p, color="0.75", lw=3.5)
    key = set()
    colors = {"symmetric": "C0", "asymmetric": "C3", "R2": "C2"}
    labelled = set()
    for name, sub in t.groupby("branch", sort=False):
        color = colors[name.split()[0]]
        family = name if name.startswith("symmetric") or name.startswith("R2") else "asymmetric (switched at BPs)"
        label = None if family in labelled else (r"unequal pair $R_2$ = %g" % IMPERFECT_R2
                                                   if name.startswith("R2") else family)
        labelled.add(family)
        _, drawn = style.draw_branch(left, sub, "control", "pressure", color=color, label=label)
        key |= drawn | style.mark_critical(left, sub, "control", "pressure")
        for column, ls_color in (("stretch_1", color), ("stretch_2", color)):
            style.draw_branch(right, sub, "control", column, color=ls_color, lw=1.0)
        style.mark_critical(right, sub, "control", "stretch_1")
    left.set_ylabel(style.label("pressure"))
    right.set_ylabel(r"stretch of each balloon $\lambda_1$, $\lambda_2$")
    left.set_ylim(0.0115, 0.0150)
    left.set_title("two balloons, one chamber, V prescribed")
    right.set_title(r"$\lambda_1$ and $\lambda_2$ (N = 101)")
    style.legend(right, key=key)
    left.legend(loc="lower right", fontsize=8)
    style.save(fig, path)


def main(argv=None):
    args = parse_args(__doc__, argv, lambda p: p.add_argument("--speed", action="store_true",
                                                             help="time the must-show run (N = 101) only"))
    if args.speed:
        table = speed()
        save(args, "two_balloons.speed", table, load_average_1min=round(os.getloadavg()[0], 2),
             ratio_default_to_target_3=round(float(table["wall_s"].iloc[0] / table["wall_s"].iloc[1]), 3))
        print(table.to_string(index=False))
        return table
    sizes = [51, 101] if args.quick else [51, 101, 201]
    table = errors(sizes)
    save(args, "two_balloons", table, sizes=sizes, R=10.0, H=0.1, c1=0.4375, c2=0.0625)
    branches = {**pair_branches(101), **pair_branches(101, IMPERFECT_R2)}
    t = branch_table(branches)
    save(args, "two_balloons.branches", t, nodes=101, imperfect_R2=IMPERFECT_R2)
    draw(t, args.out / "two_balloons.png")
    with pd.option_context("display.width", 200):
        print(table.to_string(index=False))
    return table


if __name__ == "__main__":
    main()
