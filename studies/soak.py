"""Soak: thousands of random designs through one sweep; no crash, no hang, a count of statuses.

Random scene (plate, balloon, torus), mesh, law, constants, voltage and pressure (from well below
to well beyond the limit point, negative included, a few deliberately invalid): each design is one
equilibrium from rest with a per-design time limit. The rows go to --out (CSV, resumable), the
settings to a JSON sidecar, the status counts to stdout and --out with .summary.json.

    python studies/soak.py --out soak.csv            # 10,000 designs
    python studies/soak.py --quick --out soak.csv    # 200 designs
"""

import argparse
import json
from pathlib import Path

import numpy as np

from snapmem.sweeps.sweep import EquilibriumJob, sweep

SIZE = {"plate": ("R", 7.5, 0.5), "balloon": ("R", 10.0, 0.1), "torus": ("Rb", 10.0, 0.1)}
COLUMNS = ["volume", "u_max", "stretch_max", "min_tension", "deflection", "stretch", "outer_radius",
           *EquilibriumJob.REPORT]


def designs(count, seed):
    rng = np.random.default_rng(seed)
    out = []
    for i in range(count):
        scene = str(rng.choice(list(SIZE)))
        _, size, H = SIZE[scene]
        H *= float(np.exp(rng.uniform(-1, 1)))
        out.append({"i": i, "scene": scene, "nodes": int(rng.integers(5, 31)),
                    "material": str(rng.choice(["mooney_rivlin", "neo_hookean", "gent", "yeoh"])),
                    "c1": float(rng.uniform(0.05, 0.6)), "c2": float(rng.uniform(0.0, 0.2)),
                    "Jlim": float(np.exp(rng.uniform(np.log(0.05), np.log(300)))), "H": H,
                    "ratio": float(rng.uniform(0.05, 1.05)),          # torus Rs/Rb; >= 1 is invalid
                    "E_hat": float(rng.choice([0.0, rng.uniform(0, 0.4)])),
                    "pressure": float(rng.uniform(-0.3, 1.5) * 1.5 * H / size)})
    return out


def soak_job(design):
    d = dict(design)
    scene, ratio = d.pop("scene"), d.pop("ratio")
    d.pop("i")
    name, size, _ = SIZE[scene]
    d[name] = size
    if scene == "torus":
        d["Rs"] = ratio * size
    return EquilibriumJob(scene)(d)


soak_job.columns = COLUMNS

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="200 designs")
    parser.add_argument("--count", type=int, default=10_000)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--timeout", type=float, default=60.0, help="per-design time limit [s]")
    parser.add_argument("--workers", type=int)
    parser.add_argument("--out", default="soak.csv")
    args = parser.parse_args()
    count = 200 if args.quick else args.count
    out = Path(args.out)
    out.with_suffix(".json").write_text(json.dumps({**vars(args), "count": count}, indent=1))
    table = sweep(soak_job, designs(count, args.seed), out, workers=args.workers, timeout=args.timeout)
    counts = {str(k): int(v) for k, v in table["status"].value_counts().items()}
    out.with_suffix(".summary.json").write_text(json.dumps({"rows": len(table), "statuses": counts}, indent=1))
    print(f"{len(table)} rows: " + ", ".join(f"{s} {n}" for s, n in sorted(counts.items())))
