"""Tutorial 3: a sweep on Dask.

A sweep runs one job per design and writes one CSV row the moment each finishes; rerun it and the
designs already in the file are skipped (a killed sweep resumes). ``scheduler="local"`` starts a
local Dask cluster (``pip install "snapmem[dask]"``); ``scheduler="tcp://HOST:PORT"`` uses a
cluster you started with ``dask scheduler`` / ``dask worker``; ``scheduler=None`` uses the local
process pool. The rows do not depend on which: the finished file is rewritten in design order.

Here: the balloon's equilibrium stretch on its stable branch for six pressures below the limit
point, against the exact stretch of docs/MODEL.md. The same from the shell::

    snapmem sweep balloon --grid pressure=0.002:0.012:6 --set nodes=41 --out sweep.csv --scheduler local

    python docs/tutorials/t3_sweep_dask.py [--quick] [--scheduler local|tcp://HOST:PORT|pool]
"""

import numpy as np

from snapmem.reference import exact
from snapmem.sweeps.sweep import equilibrium_job, sweep

from _common import parse


def main(argv=None):
    args = parse(__doc__, argv, scheduler={"default": "local", "help": "'local', tcp://HOST:PORT or 'pool'"})
    scheduler = None if args.scheduler == "pool" else args.scheduler
    nodes = 41 if args.quick else 101
    pressures = [float(p) for p in np.linspace(0.002, 0.012, 6)]
    out = args.out / f"balloon_sweep_{args.scheduler.replace(':', '_').replace('/', '')}.csv"
    out.unlink(missing_ok=True)
    job = equilibrium_job("balloon", fixed={"nodes": nodes})
    table = sweep(job, {"pressure": pressures}, out, workers=2, scheduler=scheduler, progress=False)
    table["stretch_exact"] = [exact.balloon_stretch(p) for p in table["pressure"]]
    for _, row in table.iterrows():
        print(f"p_hat = {row['pressure']:.4f}: stretch = {row['stretch']:.6g} (exact {row['stretch_exact']:.6g}), "
              f"{row['status']}")
    return table


if __name__ == "__main__":
    main()
