"""Result files: CSV tables that pandas reads back, with the parameters beside them as JSON."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pandas as pd

from . import __version__


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


def read_meta(path) -> dict:
    """The JSON sidecar of a table written by :func:`write_table`."""
    return json.loads(Path(str(path) + ".json").read_text())
