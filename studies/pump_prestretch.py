"""The fluid pump (Gent plate, paper Fig. 6) mounted at prestretch 1, 2 and 3: snap pressure and
pumped volume.

The plate keeps its mounted radius R = 0.1 m and thickness H = 0.1 mm (so the film is cut H lp^2
thick and stretched lp times onto the rim); the law is evaluated at the total stretch (scene
parameter ``prestretch``). For each prestretch and phi in {0, 300} V, the p-V branch is traced to
volume 0.5 m^3 or pressure 2500 Pa; its snaps (:func:`snapmem.viz.style.snaps`: from each limit point to the stable
branch at the same pressure) give the snap pressure and the volume the snap pumps.
Writes results/pump_prestretch.csv (the branches) and results/pump_prestretch_snaps.csv.
"""

import pandas as pd

from snapmem import build_scene
from snapmem.continuation import ContinuationOptions, trace
from snapmem.study import parse_args, save
from snapmem.viz.style import snaps


def main(argv=None):
    args = parse_args(__doc__, argv)
    nodes = 31 if args.quick else 61
    rows, summary = [], []
    for lp in (1.0, 2.0) if args.quick else (1.0, 2.0, 3.0):
        for phi in (0.0, 300.0):
            scene = build_scene("pump", nodes=nodes, voltage=phi, pressure=5.0, prestretch=lp)   # p = 0: slack
            branch = trace(scene, "pressure", until={"volume": 0.5, "pressure": 2500.0},
                           options=ContinuationOptions(max_steps=1500))
            table = branch.table.assign(prestretch=lp, phi=phi)
            rows.append(table)
            found = snaps(table, "volume", "pressure")
            loading = [s for s in found if s[1][0] > s[0][0]]
            limits = branch.limit_points()
            first = limits.iloc[0] if len(limits) else None
            after = loading[0][1][0] if loading else float("nan")          # NaN: no well-posed far branch
            summary.append({"prestretch": lp, "phi": phi, "limit_points": len(limits),
                            "snap_pressure": first["pressure"] if first is not None else float("nan"),
                            "volume_before": first["volume"] if first is not None else float("nan"),
                            "volume_after": after,
                            "pumped_volume": after - first["volume"] if first is not None else 0.0,
                            "pressure_at_0.01_m3": float(table.loc[(table["volume"] - 0.01).abs().idxmin(), "pressure"]),
                            "ends": branch.outcome.value,
                            "status": branch.status})
    snaps_table = pd.DataFrame(summary)
    save(args, "pump_prestretch", pd.concat(rows, ignore_index=True), nodes=nodes)
    save(args, "pump_prestretch_snaps", snaps_table, nodes=nodes)
    print(snaps_table.to_string(index=False))
    return snaps_table


if __name__ == "__main__":
    main()
