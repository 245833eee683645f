"""The machine's two states, seen in a robot's real-time factor: one scene with a viscoelastic
membrane (studies/viscous_speed.py's network) run back to back in one process for ``--seconds``,
each run followed by that study's reference loop (a fixed pure-Python loop, no snapmem code).

The project's shared 2-core machine runs either fast (the loop takes about 7 ms) or slow (11-12 ms,
for seconds to hours), and every timing slows with it. A run counts as slow when its reference
exceeds ``--slow-above`` ms. The summary gives, per scene, the median real-time factor of single
runs (not medians of repeats), the share and median of each state, and the share of runs at or
above 100x real time.

Writes results/speed_states.csv (the summary), results/speed_states_runs.csv (every run: its
start [s], wall time [ms], reference [ms]) and results/speed_states.png.

    PYTHONPATH=$PWD python studies/speed_states.py [--scenes ball_drop,ball_throw] [--seconds 90]
"""

import os
import sys
import time

import numpy as np
import pandas as pd

os.environ.setdefault("SNAPMEM_COLD", "compile")      # timings of compiled kernels (see viscous_speed)
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from viscous_speed import reference_loop, timed, viscous_parameters  # noqa: E402

from snapmem.catalog.robots import experiment  # noqa: E402
from snapmem.study import parse_args, save  # noqa: E402


def extra(parser):
    parser.add_argument("--scenes", default="ball_drop,ball_throw", help="robot scenes, comma-separated")
    parser.add_argument("--seconds", type=float, default=90.0, help="how long to run each scene [s]")
    parser.add_argument("--slow-above", type=float, default=9.0, help="reference [ms] above which a run is slow")


def runs_of(name: str, seconds: float) -> pd.DataFrame:
    """Every run of scene ``name`` (viscous) for ``seconds``: start [s], wall [ms], reference [ms]."""
    params = viscous_parameters(name)
    timed(name, **params)                              # loads the compiled kernels
    rows, start = [], time.perf_counter()
    while time.perf_counter() - start < seconds:
        begun = time.perf_counter() - start
        wall = timed(name, **params)[0]
        rows.append({"scene": name, "start_s": begun, "wall_ms": 1e3 * wall, "reference_ms": 1e3 * reference_loop()})
    table = pd.DataFrame(rows)
    table["real_time_factor"] = experiment(name).t_end / (1e-3 * table["wall_ms"])
    return table


def summary(runs: pd.DataFrame, slow_above: float) -> dict:
    rtf, slow = runs["real_time_factor"], runs["reference_ms"] > slow_above
    return {"scene": runs["scene"].iloc[0], "runs": len(runs), "seconds": float(runs["start_s"].iloc[-1]),
            "rtf_median": float(rtf.median()), "rtf_10th_percentile": float(rtf.quantile(0.1)),
            "fast_share": float(1.0 - slow.mean()), "rtf_fast_median": float(rtf[~slow].median()),
            "slow_share": float(slow.mean()), "rtf_slow_median": float(rtf[slow].median()) if slow.any() else np.nan,
            "share_at_least_100x": float((rtf >= 100.0).mean()),
            "reference_fast_ms": float(runs["reference_ms"][~slow].median()),
            "reference_slow_ms": float(runs["reference_ms"][slow].median()) if slow.any() else np.nan}


def plot(runs: pd.DataFrame, slow_above: float, path) -> None:
    from snapmem.viz.style import axes, save as save_figure
    names = list(dict.fromkeys(runs["scene"]))
    fig, grid = axes(nrows=2, ncols=len(names), squeeze=False, sharex="col")
    for column, name in enumerate(names):
        own = runs[runs["scene"] == name]
        slow = own["reference_ms"] > slow_above
        top, bottom = grid[0, column], grid[1, column]
        for ax, y in ((top, "real_time_factor"), (bottom, "reference_ms")):
            named = ax is top                              # the states' key once, beside the top row
            ax.plot(own["start_s"][~slow], own[y][~slow], ".", ms=2, color="C0", label="fast state" if named else None)
            ax.plot(own["start_s"][slow], own[y][slow], ".", ms=2, color="C3", label="slow state" if named else None)
        top.axhline(100.0, color="k", lw=0.8, ls="--", label="100x real time")
        top.set_title(f"{name}, viscoelastic (single runs)")
        top.set_ylabel("real-time factor [-]")
        bottom.axhline(slow_above, color="0.4", lw=0.8, ls=":", label=f"slow above {slow_above:g} ms")
        bottom.set_ylabel("reference loop [ms]")
        bottom.set_xlabel("time since the first run [s]")
    grid[0, -1].legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, markerscale=4)
    grid[1, -1].legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, markerscale=4)
    save_figure(fig, path)


def main(argv=None):
    args = parse_args(__doc__, argv, extra)
    seconds = 2.0 if args.quick else args.seconds
    runs = pd.concat([runs_of(name, seconds) for name in args.scenes.split(",")], ignore_index=True)
    table = pd.DataFrame([summary(runs[runs["scene"] == name], args.slow_above) for name in dict.fromkeys(runs["scene"])])
    save(args, "speed_states", table, seconds_per_scene=seconds, slow_above_ms=args.slow_above)
    save(args, "speed_states_runs", runs, seconds_per_scene=seconds)
    plot(runs, args.slow_above, args.out / "speed_states.png")
    print(table.to_string(index=False))
    return table


if __name__ == "__main__":
    main()
