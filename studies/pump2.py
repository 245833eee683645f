"""The dual-membrane pump (``pump2``) against the single-membrane pump (``pump``) at equal voltage.

``pump`` is the paper's Fig. 6 plate (Gent, R = 0.1 m, H = 0.1 mm, mu = 45 kPa, Jlim = 270)
under its pressure schedule (10 Pa/s up from 5 s to 15 s, voltage off at 15 s, down from 20 s);
``pump2`` is the same active plate with a passive Mooney-Rivlin plate of twice its radius on one
fluid chamber, under a flow schedule (0.05 m^3/s in from 5 s to 15 s, voltage off at 15 s, out
from 20 s; snapmem.catalog.pump2 says why this passive membrane). For each voltage phi, both
cycles are simulated (their experiments' own schemes and tolerances) and their events taken:
the snap, the snap back and the volume pumped per cycle (the active plate's volume given up when
the voltage is switched off, V(t_hold) - V(t_down)). A cycle *works* when it completes with a
snap, a snap back and a pumped volume over 1e-3 m^3; the voltages where it does are its window.

The pump2 cycle at 300 V is run again at a 4x tighter time tolerance: its events' relative
differences (the accuracy check) are in pump2.convergence.csv, with both runs' real-time factors
(t_end over the median wall time of TIMING_RUNS warm runs; the step is the compiled bordered one,
snapmem.dynamics.compiled_chambers).

Writes pump2.csv (one row per device and voltage), pump2.cycles.csv (both cycles at 300 V in
time), pump2.convergence.csv and pump2.png.
"""

import math

import numpy as np
import pandas as pd

from snapmem.catalog.robots import events, run
from snapmem.errors import SnapmemError
from snapmem.study import parse_args, save
from snapmem.viz import style

WORKS_VOLUME = 1e-3            # [m^3]: a cycle pumping less does not work
CYCLE_VOLTAGE = 300.0          # [V]: the cycle drawn and checked at a tighter tolerance
TIMING_RUNS = 5                # warm runs whose median wall time gives a real-time factor


def cycle(device: str, voltage: float, **params):
    """(events row, trajectory or None) of one cycle of ``device`` at ``voltage`` [V]."""
    row = {"device": device, "voltage": voltage}
    try:
        traj = run(device, voltage=voltage, **params)
    except SnapmemError as exc:             # a run that cannot start: recorded, not a crash
        return {**row, "status": f"failed: {exc}", "works": False}, None
    p = traj.meta["parameters"]
    found = events(traj) if traj.meta["status"] == "completed" else {}
    key = "volume_1" if device == "pump2" else "volume"
    held, lowered = np.interp([p["t_hold"], p["t_down"]], traj["t"], traj[key])
    pumped = float(held - lowered)
    wall = traj.meta["wall_time"]
    row.update(status=traj.meta["status"], snap=found.get("snap", math.nan),
               snap_back=found.get("snap_back", math.nan), pumped_volume=pumped,
               wall_time=wall, real_time_factor=traj.meta["t_end"] / wall, steps=traj.meta["steps"])
    row["works"] = bool(row["status"] == "completed" and np.isfinite(row["snap"]) and np.isfinite(row["snap_back"])
                        and pumped > WORKS_VOLUME)
    return row, traj


def cycles_table(trajectories: dict) -> pd.DataFrame:
    tables = []
    for device, traj in trajectories.items():
        t = pd.DataFrame({"t": traj["t"], "pressure": traj["load_pressure"]})
        if device == "pump2":
            t["volume_active"], t["volume_passive"] = traj["volume_1"], traj["volume_2"]
        else:
            t["volume_active"], t["volume_passive"] = traj["volume"], np.nan
        t.insert(0, "device", device)
        tables.append(t)
    return pd.concat(tables, ignore_index=True)


def draw(summary: pd.DataFrame, cycles: pd.DataFrame, path) -> None:
    """Left: both cycles at 300 V in time (volumes, and the chamber pressure below). Right: the
    volume pumped per cycle against the voltage (filled: the cycle works)."""
    fig, axs = style.axes(nrows=2, ncols=2, sharex="col", gridspec_kw={"height_ratios": [2, 1]})
    (volume_ax, window_ax), (pressure_ax, empty) = axs
    colors = {"pump": "C0", "pump2": "C3"}
    names = {"pump": "pump (one plate, p prescribed)", "pump2": "pump2 (active + passive, flow prescribed)"}
    for device, sub in cycles.groupby("device", sort=False):
        volume_ax.plot(sub["t"], sub["volume_active"], color=colors[device], label=names[device] + ": active $V_1$")
        if device == "pump2":
            volume_ax.plot(sub["t"], sub["volume_passive"], color=colors[device], ls="--",
                           label=names[device] + ": passive $V_2$")
        pressure_ax.plot(sub["t"], sub["pressure"], color=colors[device])
    for device, sub in summary.groupby("device", sort=False):
        at = sub[sub["voltage"] == CYCLE_VOLTAGE]
        for _, row in at.iterrows():
            for event, marker in (("snap", ">"), ("snap_back", "<")):
                if np.isfinite(row[event]):
                    volume_ax.axvline(row[event], color=colors[device], lw=0.6, ls=":")
        works = sub["works"].astype(bool)
        window_ax.plot(sub["voltage"], sub["pumped_volume"], color=colors[device], lw=1.0)
        window_ax.plot(sub["voltage"][works], sub["pumped_volume"][works], "o", color=colors[device],
                       label=device + ": works")
        window_ax.plot(sub["voltage"][~works], sub["pumped_volume"][~works], "o", mfc="white", color=colors[device],
                       label=device + ": no full cycle")
    volume_ax.set_ylabel(r"active, passive volume $V_1$, $V_2$ [m$^3$]")
    volume_ax.set_title(r"cycles at $\phi$ = %g V (dotted: snap, snap back)" % CYCLE_VOLTAGE)
    pressure_ax.set_ylabel(r"chamber pressure $p$ [Pa]")
    pressure_ax.set_xlabel(r"time $t$ [s]")
    window_ax.set_ylabel(r"pumped per cycle $\Delta V$ [m$^3$]")
    window_ax.set_title("volume pumped per cycle against voltage")
    window_ax.set_xlabel(r"voltage $\phi$ [V]")
    window_ax.tick_params(labelbottom=True)
    window_ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize=8)
    empty.axis("off")                 # the cycles' key, beside the pressure panel they share
    empty.legend(*volume_ax.get_legend_handles_labels(), loc="center left", fontsize=8, frameon=False)
    style.save(fig, path)


def convergence(default_traj) -> pd.DataFrame:
    """pump2's events at CYCLE_VOLTAGE against a run at a 4x tighter time tolerance."""
    tol = default_traj.meta["parameters"]["tol"]
    tight = run("pump2", voltage=CYCLE_VOLTAGE, tol=tol / 4)
    a, b = events(default_traj), events(tight)
    rows = [{"event": k, "value": a[k], "tight_value": b[k], "relative_difference": abs(a[k] / b[k] - 1)}
            for k in a]
    for name, t in (("real_time_factor", tol), ("tight_real_time_factor", tol / 4)):
        walls = [run("pump2", voltage=CYCLE_VOLTAGE, tol=t).meta["wall_time"] for _ in range(TIMING_RUNS)]
        rows.append({"event": name, "value": default_traj.meta["t_end"] / float(np.median(walls))})
    return pd.DataFrame(rows)


def redraw(folder) -> None:
    """Draw pump2.png again from the CSVs in ``folder``."""
    from pathlib import Path
    folder = Path(folder)
    draw(pd.read_csv(folder / "pump2.csv"), pd.read_csv(folder / "pump2.cycles.csv"), folder / "pump2.png")


def main(argv=None):
    args = parse_args(__doc__, argv)
    voltages = [0.0, CYCLE_VOLTAGE] if args.quick else [0.0, 100.0, 200.0, 250.0, 300.0, 350.0, 400.0, 500.0]
    rows, drawn = [], {}
    for voltage in voltages:
        for device in ("pump", "pump2"):
            row, traj = cycle(device, voltage)
            rows.append(row)
            if voltage == CYCLE_VOLTAGE and traj is not None:
                drawn[device] = traj
    summary = pd.DataFrame(rows)
    save(args, "pump2", summary, voltages=voltages, works_volume=WORKS_VOLUME)
    cycles = cycles_table(drawn)
    save(args, "pump2.cycles", cycles, voltage=CYCLE_VOLTAGE)
    save(args, "pump2.convergence", convergence(drawn["pump2"]), voltage=CYCLE_VOLTAGE)
    draw(summary, cycles, args.out / "pump2.png")


if __name__ == "__main__":
    main()
