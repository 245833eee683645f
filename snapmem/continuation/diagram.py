"""A bifurcation diagram: several branches and how they connect, saved as one set of files."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import snapmem._lazy as _lazy

pd = _lazy.module("pandas")  # imported at first use (start-up)

from snapmem.continuation.branch import Branch
from snapmem.errors import SnapmemError, read_npz
from snapmem.io.results import write_npz, write_table


@dataclass
class Connection:
    """Branch ``child`` leaves branch ``parent`` at row ``row`` of the parent's points table, in
    the direction ``sign`` (+1 or -1) of the bifurcating vector."""

    parent: int
    row: int
    child: int
    sign: int


@dataclass
class Diagram:
    """Branches (index = position in ``branches``) and the :class:`Connection` list between them.

    Saved by :meth:`save` as ``PATH`` (CSV of every branch's table with a ``branch`` column),
    ``PATH.points.csv`` (every branch's points table, with ``branch``), ``PATH.npz`` (each
    branch's states as arrays ``b<i>_x``, ``b<i>_q``, ``b<i>_lam``) and the JSON sidecar
    ``PATH.json`` (the connections, each branch's control and status, the scene). Read back by
    :func:`read_diagram`.
    """

    branches: list = field(default_factory=list)
    connections: list = field(default_factory=list)

    def add(self, branch: Branch, parent: int | None = None, row: int = -1, sign: int = 1) -> int:
        """Add ``branch`` (connected to ``parent`` at its points row ``row`` if given); its index."""
        self.branches.append(branch)
        index = len(self.branches) - 1
        if parent is not None:
            self.connections.append(Connection(parent, row, index, sign))
        return index

    @property
    def table(self) -> pd.DataFrame:
        """Every branch's table, one after the other, with a ``branch`` column first."""
        return pd.concat([b.table.assign(branch=i)[["branch", *b.table.columns]] for i, b in enumerate(self.branches)],
                         ignore_index=True)

    @property
    def points(self) -> pd.DataFrame:
        """Every branch's critical points, with a ``branch`` column first."""
        return pd.concat([b.points.assign(branch=i)[["branch", *b.points.columns]] for i, b in enumerate(self.branches)],
                         ignore_index=True)

    def meta(self) -> dict:
        first = self.branches[0]
        return {"scene": first.scene.name, "parameters": {k: str(v) for k, v in first.scene.parameters.items()},
                "branches": [{"control": b.control, "status": b.status, "outcome": b.outcome.value} for b in self.branches],
                "connections": [c.__dict__ for c in self.connections]}

    def save(self, path) -> Path:
        """Write the diagram's files (see the class docstring); returns the CSV path."""
        path = Path(path)
        write_table(self.table, path, self.meta())
        write_table(self.points, path.with_suffix(".points.csv"))
        arrays = {}
        for i, b in enumerate(self.branches):
            pb_state = [b.scene_state(p) for p in b.states]
            arrays[f"b{i}_x"] = np.array([p.x for p in b.states])
            arrays[f"b{i}_lam"] = np.array([p.lam for p in b.states])
            arrays[f"b{i}_q"] = np.array(pb_state)
        write_npz(path.with_suffix(".npz"), **arrays)
        return path


@dataclass
class SavedDiagram:
    """A diagram read back from its files: tables, states and connections (no scene objects)."""

    table: pd.DataFrame
    points: pd.DataFrame
    states: dict
    connections: list
    meta: dict

    def branch(self, i: int) -> pd.DataFrame:
        return self.table[self.table["branch"] == i]


def read_diagram(path) -> SavedDiagram:
    """Read a diagram written by :meth:`Diagram.save`."""
    path = Path(path)
    side = path.with_name(path.name + ".json")
    if not path.exists() or not side.exists():
        raise SnapmemError(f"diagram {str(path)!r}: needs {path.name} and {side.name}")
    meta = json.loads(side.read_text())
    states = read_npz(path.with_suffix(".npz"), "diagram states")
    return SavedDiagram(pd.read_csv(path), pd.read_csv(path.with_suffix(".points.csv")), states,
                        [Connection(**c) for c in meta["connections"]], meta)
