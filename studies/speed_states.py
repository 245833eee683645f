"""The machine's states, seen in a robot's real-time factor: one scene run back to back in one
process for ``--seconds``, elastic and with a viscoelastic membrane (studies/viscous_speed.py's
network) in turn, each run followed by that study's reference loop (a fixed pure-Python loop, no
snapmem code).

The project's shared 2-core machine runs either fast (the loop takes about 7 ms) or slow (11-12 ms,
on some days about 20 ms, for seconds to hours), and every timing slows with it. A run counts as
slow when its reference exceeds ``--slow-above`` ms. The summary gives, per scene and membrane,
the median real-time factor of single runs (not medians of repeats), the share and median of each
state, and the share of runs at or above 100x real time; for the viscous runs also the median
ratio to the elastic run just before (the network's own cost, which the machine's state should
not move) and the share at or above 100x among the pairs whose elastic run made 100x (the
issue's "still >= 100x": where the elastic robot makes it, does the viscous one?).

Writes results/speed_states.csv (the summary), results/speed_states_runs.csv (every run: its
scene, membrane, start [s], wall time [ms], reference [ms]) and results/speed_states.png.

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
    """Runs of scene ``name`` for ``seconds``, elastic then viscous in turn (a pair shares a
    ``pair`` number): scene, membrane, pair, start [s], wall [ms], reference [ms], real-time factor."""
    variants = {"elastic": {}, "viscous": viscous_parameters(name)}
    for params in variants.values():
        timed(name, **params)                          # loads the compiled kernels
    t_end = experiment(name).t_end
    rows, start, pair = [], time.perf_counter(), 0
    while time.perf_counter() - start < seconds:
        for membrane, params in variants.items():
            begun = time.perf_counter() - start
            wall = timed(name, **params)[0]
            rows.append({"scene": name, "membrane": membrane, "pair": pair, "start_s": begun, "wall_ms": 1e3 * wall,
                         "reference_ms": 1e3 * reference_loop(), "real_time_factor": t_end / wall})
        pair += 1
    return pd.DataFrame(rows)


def summary(runs: pd.DataFrame, membrane: str, slow_above: float) -> dict:
    """The summary row of ``membrane``'s runs ('elastic' or 'viscous') among one scene's ``runs``."""
    own = runs[runs["membrane"] == membrane]
    rtf, slow = own["real_time_factor"], own["reference_ms"] > slow_above
    row = {"scene": own["scene"].iloc[0], "membrane": membrane, "runs": len(own),
           "seconds": float(runs["start_s"].iloc[-1]),
           "rtf_median": float(rtf.median()), "rtf_10th_percentile": float(rtf.quantile(0.1)),
           "fast_share": float(1.0 - slow.mean()), "rtf_fast_median": float(rtf[~slow].median()) if (~slow).any() else np.nan,
           "slow_share": float(slow.mean()), "rtf_slow_median": float(rtf[slow].median()) if slow.any() else np.nan,
           "share_at_least_100x": float((rtf >= 100.0).mean()),
           "reference_fast_ms": float(own["reference_ms"][~slow].median()) if (~slow).any() else np.nan,
           "reference_slow_ms": float(own["reference_ms"][slow].median()) if slow.any() else np.nan,
           "ratio_to_elastic_median": np.nan, "elastic_pairs_at_least_100x": 0, "share_at_least_100x_where_elastic_is": np.nan}
    if membrane == "viscous":
        pairs = own.merge(runs[runs["membrane"] == "elastic"], on="pair", suffixes=("", "_elastic"))
        ratio = pairs["real_time_factor"] / pairs["real_time_factor_elastic"]
        fast_elastic = pairs["real_time_factor_elastic"] >= 100.0
        row.update(ratio_to_elastic_median=float(ratio.median()), elastic_pairs_at_least_100x=int(fast_elastic.sum()),
                   share_at_least_100x_where_elastic_is=float((pairs["real_time_factor"][fast_elastic] >= 100.0).mean())
                   if fast_elastic.any() else np.nan)
    return row


def plot(runs: pd.DataFrame, slow_above: float, path) -> None:
    from snapmem.viz.style import axes, save as save_figure
    names = list(dict.fromkeys(runs["scene"]))
    viscous_slow = runs.loc[runs["membrane"] == "viscous", "reference_ms"] > slow_above
    seen = {"fast": bool((~viscous_slow).any()), "slow": bool(viscous_slow.any())}    # a state in the key only if run in
    fig, grid = axes(nrows=2, ncols=len(names), squeeze=False, sharex="col")
    for column, name in enumerate(names):
        own = runs[runs["scene"] == name]
        top, bottom = grid[0, column], grid[1, column]
        elastic, viscous = own[own["membrane"] == "elastic"], own[own["membrane"] == "viscous"]
        named = column == len(names) - 1                  # the key once, beside the last column
        top.plot(elastic["start_s"], elastic["real_time_factor"], ".", ms=2, color="0.65",
                 label="elastic (either state)" if named else None)
        slow = viscous["reference_ms"] > slow_above
        for ax, y in ((top, "real_time_factor"), (bottom, "reference_ms")):
            ax.plot(viscous["start_s"][~slow], viscous[y][~slow], ".", ms=2, color="C0",
                    label="viscous, fast state" if named and ax is top and seen["fast"] else None)
            ax.plot(viscous["start_s"][slow], viscous[y][slow], ".", ms=2, color="C3",
                    label="viscous, slow state" if named and ax is top and seen["slow"] else None)
        top.axhline(100.0, color="k", lw=0.8, ls="--", label="100x real time" if named else None)
        top.set_ylim(top=max(top.get_ylim()[1], 105.0))     # the threshold clear of the frame
        top.set_title(f"{name} (single runs)")
        top.set_ylabel("real-time factor [-]")
        bottom.axhline(slow_above, color="0.4", lw=0.8, ls=":", label=f"slow above {slow_above:g} ms" if named else None)
        bottom.set_ylabel("reference loop after the viscous run [ms]")
        bottom.set_xlabel("time since the first run [s]")
    grid[0, -1].legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, markerscale=4)
    grid[1, -1].legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, markerscale=4)
    save_figure(fig, path)


def main(argv=None):
    args = parse_args(__doc__, argv, extra)
    seconds = 2.0 if args.quick else args.seconds
    runs = pd.concat([runs_of(name, seconds) for name in args.scenes.split(",")], ignore_index=True)
    table = pd.DataFrame([summary(runs[runs["scene"] == name], membrane, args.slow_above)
                          for name in dict.fromkeys(runs["scene"]) for membrane in ("elastic", "viscous")])
    save(args, "speed_states", table, seconds_per_scene=seconds, slow_above_ms=args.slow_above)
    save(args, "speed_states_runs", runs, seconds_per_scene=seconds)
    plot(runs, args.slow_above, args.out / "speed_states.png")
    print(table.to_string(index=False))
    return table


if __name__ == "__main__":
    main()
