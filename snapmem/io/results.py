"""Result files: CSV tables that pandas reads back, with the parameters beside them as JSON."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import snapmem._lazy as _lazy

pd = _lazy.module("pandas")  # imported at first use (start-up)

from snapmem._version import __version__


def write_table(table: pd.DataFrame, path, meta: dict | None = None) -> Path:
    """Write ``table`` to CSV at ``path`` and ``meta`` to the JSON sidecar ``path`` + '.json'.

    Written to a temporary file and renamed, so an interrupted run never leaves half a file.
    """
    path = Path(path)
    if path.parent and not path.parent.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    table.to_csv(tmp, index=False)
    os.replace(tmp, path)
    if meta is not None:
        side = path.with_name(path.name + ".json")
        tmp = side.with_name(side.name + ".tmp")
        tmp.write_text(json.dumps({"snapmem": __version__, **meta}, indent=2, default=str))
        os.replace(tmp, side)
    return path


def write_npz(path, **arrays) -> Path:
    """Write ``arrays`` as a compressed .npz at ``path`` ('.npz' appended if missing, as numpy does).

    Written to a temporary file and renamed, so an interrupted run never leaves half a file.
    """
    path = Path(path)
    if path.suffix != ".npz":
        path = path.with_name(path.name + ".npz")
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, "wb") as handle:
            np.savez_compressed(handle, **arrays)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)                    # only left if the write did not finish
    return path

