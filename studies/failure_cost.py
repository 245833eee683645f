"""Benchmark: what checking for failure costs a trace (issue 15: "checking failure adds <= 10% to a
trace").

Each VHB design of studies/actuation_window.py (Gent, mu = 50 kPa, Jlim = 110, eps = 4.5 eps0) is
traced as there (the balloon in voltage at a held pressure and in pressure at a held voltage, the
pump plate and the torus in voltage), with its failure checks (``E_breakdown`` with its
``breakdown_exponent``, ``stretch_limit``: the breakdown and rupture margins of every point, and
the EB and RU events located where a margin reaches 1) and without them (the same scene with
neither parameter), the two alternated in one process. The cost is the median of the paired
ratios of wall times, with over without, so that the shared machine's state falls on both alike;
the 10th and 90th percentiles of the ratios show the spread. Loss of tension and of ellipticity
(LT, LE) are checked in both runs (they are the bifurcation events' too), so they are not part
of the difference.

Writes results/failure_cost.csv.

    PYTHONPATH=$PWD python studies/failure_cost.py [--quick] [--pairs 21]
"""

import time

import numpy as np
import pandas as pd

from snapmem import build_scene
from snapmem.continuation.tracer import trace
from snapmem.study import parse_args, save

EPS0 = 8.854e-12
MATERIAL = dict(material="gent", mu=5e4, Jlim=110.0, eps=4.5 * EPS0)
FAILURE = dict(E_breakdown=35e6, breakdown_exponent=0.565, stretch_limit=6.0)
# name, scene, its geometry and the held load, the control, where the trace stops
DESIGNS = [("balloon", "balloon", dict(R=0.02, H=2e-4, pressure=300.0, voltage=0.0), "voltage", {"stretch_max": 3.0}),
           ("balloon", "balloon", dict(R=0.02, H=2e-4, pressure=0.0, voltage=2000.0), "pressure", {"stretch_max": 4.35}),
           ("pump plate", "pump", dict(pressure=20.0, voltage=0.0), "voltage", {"stretch_max": 6.0}),
           ("torus", "torus", dict(Rb=0.1, Rs=0.02, H=1e-4, pressure=100.0, voltage=0.0), "voltage",
            {"stretch_max": 3.0})]


def timed_trace(scene, control, until):
    start = time.perf_counter()
    branch = trace(scene, control, until=until)
    return time.perf_counter() - start, branch


def main(argv=None):
    args = parse_args(__doc__, argv, extra=lambda p: p.add_argument("--pairs", type=int, default=21,
                                                                    help="alternated runs of each design"))
    nodes, pairs = (31, 3) if args.quick else (101, args.pairs)
    rows = []
    for name, scene_name, setting, control, until in DESIGNS:
        scenes = {checked: build_scene(scene_name, nodes=nodes, with_loads=("voltage",), **MATERIAL, **setting,
                                       **(FAILURE if checked else {}))
                  for checked in (True, False)}
        branches = {checked: timed_trace(scene, control, until)[1]            # untimed: loads the kernels
                    for checked, scene in scenes.items()}
        times = {True: [], False: []}
        for i in range(pairs):
            for checked in ((True, False) if i % 2 else (False, True)):
                times[checked].append(timed_trace(scenes[checked], control, until)[0])
        ratios = np.array(times[True]) / np.array(times[False])
        checked, plain = branches[True], branches[False]
        rows.append({"design": name, "control": control, "nodes": nodes, "pairs": pairs,
                     "points": len(checked.table), "points_unchecked": len(plain.table),
                     "events_checked": " ".join(str(k) for k in checked.points["kind"]),
                     "events_unchecked": " ".join(str(k) for k in plain.points["kind"]),
                     "wall_checked_ms": 1e3 * float(np.median(times[True])),
                     "wall_unchecked_ms": 1e3 * float(np.median(times[False])),
                     "cost_ratio_median": float(np.median(ratios)),
                     "cost_ratio_p10": float(np.percentile(ratios, 10)),
                     "cost_ratio_p90": float(np.percentile(ratios, 90))})
        print(pd.DataFrame(rows[-1:]).to_string(index=False), flush=True)
    table = pd.DataFrame(rows)
    save(args, "failure_cost", table, material=MATERIAL, failure=FAILURE)
    print(table.to_string(index=False))
    return table


if __name__ == "__main__":
    main()
