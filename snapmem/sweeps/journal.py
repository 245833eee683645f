"""The row file of a sweep: one CSV line per finished design, and the metadata beside it.

The file is append-only while the sweep runs (each row flushed and fsynced at once), repaired
after a kill (a last line cut short is dropped), locked against a second sweep writing to it, and
rewritten in design order when every design is done. ``<out>.sweep.json`` (one per output file:
``r.csv.sweep.json`` beside ``r.csv``) keeps what the rows depend on besides the design and the
whole grid (every design's values and key, in order); resuming with other settings or another
grid is refused, and so is a file whose rows are not this grid's (edited, duplicated) or that is
no sweep's journal at all, before anything in it is changed.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
import os
from numbers import Integral, Real

import numpy as np

from snapmem.errors import SnapmemError
from snapmem.io.results import fsync_folder

log = logging.getLogger(__name__)

#: The first columns of every row file: the design's index in the grid and its key.
LEADING = ("design", "key")


def cell(value) -> str:
    """A value as a CSV cell: empty for None and non-finite numbers, floats exact (repr), one line."""
    if value is None:
        return ""
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (Integral, np.integer)):
        return str(int(value))
    if isinstance(value, (Real, np.floating)):
        value = float(value)
        return repr(value) if math.isfinite(value) else ""
    return " ".join(str(value).split())          # one line: newlines and tabs become spaces


class RowFile:
    """The CSV of a sweep: append-only while it runs, repaired after a kill, locked against a
    second sweep writing to it at the same time, and checked against its grid.

    An existing file is taken as this sweep's journal only if its header is this sweep's, its
    metadata file (:func:`meta_path`) holds the same ``meta`` and the same grid (every design's
    values, in order), and every row is a design of that grid with the parameters the grid gives
    it, each design at most once. Anything else is refused (SnapmemError) before the file is
    touched; only then is a last line cut short by a kill dropped.

    Parameters
    ----------
    path : path
        The CSV file.
    names : list of str
        The designs' parameter names (columns after ``design`` and ``key``).
    designs : list of dict
        Every design of the grid, in order.
    keys : list of str
        Their keys (:func:`snapmem.sweeps.grid.design_key`).
    meta : dict
        What the rows depend on besides the design (job, scene, fixed parameters).
    """

    def __init__(self, path, names: list[str], designs: list[dict] | None = None, keys: list[str] | None = None,
                 meta: dict | None = None):
        self.path = os.fspath(path)
        self.names = names
        self.designs = designs
        self.keys = keys
        self.index = None if keys is None else {key: i for i, key in enumerate(keys)}
        self.meta = None if meta is None else json.loads(json.dumps({**meta, "grid": grid_record(names, designs, keys)}))
        self.outputs = None              # output column names, once the header is known
        self.done = {}                   # key -> design index of rows already in the file
        folder = os.path.dirname(os.path.abspath(self.path))
        if not os.path.isdir(folder):
            raise SnapmemError(f"out = {self.path!r}: folder {folder!r} does not exist")
        if os.path.isdir(self.path):
            raise SnapmemError(f"out = {self.path!r}: is a folder, must be a CSV file")
        existed = os.path.exists(self.path)
        try:
            self.fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise SnapmemError(f"out = {self.path!r}: cannot open ({exc.strerror})") from None
        try:
            import fcntl
            fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except ImportError:              # not POSIX: no lock
            pass
        except OSError:
            os.close(self.fd)
            raise SnapmemError(f"out = {self.path!r}: another sweep is writing to this file") from None
        try:
            self._read()
        except BaseException:
            os.close(self.fd)
            if not existed and os.path.exists(self.path) and os.path.getsize(self.path) == 0:
                os.unlink(self.path)     # refused before anything was written: leave no empty file
            raise

    def _refuse(self, why: str):
        raise SnapmemError(f"out = {self.path!r}: {why}; the file is left as it was: choose a new file, "
                           "or resume with the command that made it")

    def _read(self):
        data = b""
        while True:
            chunk = os.pread(self.fd, 1 << 20, len(data))
            if not chunk:
                break
            data += chunk
        if not data:                                  # a new sweep
            if self.meta is not None:
                write_meta(self.path, self.meta)
            return
        # everything is checked before the file is touched: a file that is not this sweep's own
        # journal stays byte for byte as it was
        end = data.find(b"\n")
        if end < 0:
            self._refuse("is not a sweep's CSV (no complete first line)")
        try:
            text = data[:data.rfind(b"\n") + 1].decode("utf-8")
            rows = list(csv.reader(io.StringIO(text)))
        except (UnicodeDecodeError, csv.Error) as exc:
            self._refuse(f"is not a sweep's CSV ({exc})")
        header = rows[0]
        head = [*LEADING, *self.names, "status"]
        if header[:len(head)] != head or header[-1:] != ["message"]:
            raise SnapmemError(f"out = {self.path!r}: has columns {', '.join(header)}; this sweep writes "
                               f"{', '.join(head)}, ..., message: resume with the same grid or choose a new file "
                               "(the file is left as it was)")
        if self.meta is not None:
            self._check_meta()
        self.outputs = header[len(head):-1]
        lines = {}
        for line, row in enumerate(rows[1:], start=2):
            if len(row) != len(header):
                raise SnapmemError(f"out = {self.path!r}: line {line} has {len(row)} fields, the header "
                                   f"{len(header)}: the file is damaged; repair or remove that line")
            key = row[1]
            if key in lines:
                raise SnapmemError(f"out = {self.path!r}: design {row[0]} (key {key}) is there twice, lines "
                                   f"{lines[key]} and {line}: the file is damaged; remove one of them")
            lines[key] = line
            if self.index is not None:
                self._check_row(line, row)
            self.done[key] = row[0]
        if not data.endswith(b"\n"):                 # a line cut short by a kill: drop it, now that
            keep = data.rfind(b"\n") + 1             # the file is known to be this sweep's
            log.warning("%s: dropped a partial last line (%d bytes) left by an interrupted sweep",
                        self.path, len(data) - keep)
            os.ftruncate(self.fd, keep)
            os.fsync(self.fd)

    def _check_row(self, line: int, row: list[str]):
        """A row must be a design of this grid, numbered as the grid numbers it, with its parameters."""
        key = row[1]
        if key not in self.index:
            raise SnapmemError(f"out = {self.path!r}: line {line}: key {key!r} is no design of this grid: the row "
                               "was edited or comes from another sweep; remove it")
        i = self.index[key]
        expected = [str(i), key, *(cell(self.designs[i][n]) for n in self.names)]
        if row[:len(expected)] != expected:
            got = dict(zip([*LEADING, *self.names], row))
            want = dict(zip([*LEADING, *self.names], expected))
            diff = ", ".join(f"{k} = {got[k]!r} (the grid's {want[k]!r})" for k in want if got[k] != want[k])
            raise SnapmemError(f"out = {self.path!r}: line {line} was edited: {diff}; remove it or restore it")

    def _check_meta(self):
        side = meta_path(self.path)
        legacy = os.path.splitext(self.path)[0] + ".sweep.json"      # where snapmem < 0.13 kept it
        source = side if os.path.exists(side) else legacy if os.path.exists(legacy) else None
        if source is None:
            self._refuse(f"has no {os.path.basename(side)} beside it, so it is no journal of a sweep")
        try:
            with open(source, encoding="utf-8") as f:
                old = json.load(f)
        except (OSError, ValueError) as exc:
            self._refuse(f"{source} cannot be read ({exc})")
        if not isinstance(old, dict):
            self._refuse(f"{source} is not a sweep's metadata")
        meta = self.meta
        if "grid" not in old:                        # an older journal: its rows are checked one by one
            meta = {k: v for k, v in meta.items() if k != "grid"}
        if old != meta:
            changed = sorted(k for k in set(old) | set(meta) if old.get(k) != meta.get(k) and k != "grid")
            if changed:
                raise SnapmemError(f"out = {self.path!r}: was written with {', '.join(f'{k} = {old.get(k)!r}' for k in changed)}; "
                                   f"this sweep has {', '.join(f'{k} = {meta.get(k)!r}' for k in changed)}: "
                                   "resume with the same settings or choose a new file")
            raise SnapmemError(f"out = {self.path!r}: was written for another grid ({grid_difference(old['grid'], meta['grid'])}): "
                               "resume with the same --grid (values and order) or choose a new file")
        if source != side:
            write_meta(self.path, self.meta)

    @property
    def header(self) -> list[str]:
        return [*LEADING, *self.names, "status", *self.outputs, "message"]

    def _write(self, rows: list[list[str]]):
        buffer = io.StringIO()
        csv.writer(buffer, lineterminator="\n").writerows(rows)
        view = memoryview(buffer.getvalue().encode("utf-8"))
        end = os.lseek(self.fd, 0, os.SEEK_END)
        while view:                                   # a kill between two writes leaves a partial line
            n = os.pwrite(self.fd, view, end)
            view, end = view[n:], end + n
        os.fsync(self.fd)

    def start(self, outputs: list[str]):
        """Write the header with these output columns (a new file)."""
        self.outputs = list(outputs)
        self._write([self.header])

    def append(self, index: int, key: str, design: dict, result: dict):
        """Append one finished design (outputs not in the header are named in the message)."""
        outputs = result["outputs"]
        extra = [name for name in outputs if name not in self.outputs]
        message = result["message"]
        if extra:
            message = (message + " " if message else "") + f"(outputs not in the file's columns, dropped: {', '.join(extra)})"
        row = [str(index), key, *(cell(design[n]) for n in self.names), result["status"],
               *(outputs.get(n, "") for n in self.outputs), message]
        self._write([row])
        self.done[key] = str(index)

    def finish(self):
        """Rewrite the file in design order (atomically: a kill leaves the old file whole)."""
        with open(self.path, newline="", encoding="utf-8") as f:
            rows = list(csv.reader(f))
        if len(rows) <= 1:
            return
        rows[1:] = sorted(rows[1:], key=lambda row: (int(row[0]), row[1]))
        tmp = self.path + ".tmp"
        try:
            with open(tmp, "w", newline="", encoding="utf-8") as f:
                csv.writer(f, lineterminator="\n").writerows(rows)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, self.path)
        finally:
            if os.path.exists(tmp):                  # interrupted before the rename: the old file is whole
                os.unlink(tmp)
        fsync_folder(os.path.dirname(os.path.abspath(self.path)))

    def close(self):
        os.close(self.fd)


def meta_path(path) -> str:
    """The metadata file of the sweep CSV ``path``: ``path`` + '.sweep.json' (one per output file)."""
    return os.fspath(path) + ".sweep.json"


def grid_record(names, designs, keys) -> dict | None:
    """The whole grid as the metadata keeps it: parameter names, every design's values and key, in order."""
    if designs is None:
        return None
    return {"names": list(names), "values": [[d[n] for n in names] for d in designs], "keys": list(keys)}


def grid_difference(old: dict, new: dict) -> str:
    """Where two grid records first differ, in words."""
    a, b = old.get("keys", []), new.get("keys", [])
    if len(a) != len(b):
        return f"{len(a)} designs there, {len(b)} here"
    i = next(i for i, (x, y) in enumerate(zip(a, b)) if x != y)
    there, here = (dict(zip(g["names"], g["values"][i])) for g in (old, new))
    note = " (0 and 0.0 are different values: write the grid as it was)" if there == here else ""
    return f"design {i} is {there} there, {here} here{note}"


def write_meta(path, meta: dict):
    """Write a sweep's metadata beside its CSV ``path`` (atomically)."""
    side = meta_path(path)
    tmp = side + ".tmp"
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump(meta, f, indent=1, sort_keys=True)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, side)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def read_rows(path):
    """A sweep's CSV as a pandas DataFrame (parameters and outputs typed, empty cells NaN)."""
    import pandas as pd
    return pd.read_csv(path, dtype={"key": str, "status": str, "message": str}, keep_default_na=False,
                       na_values=[""])
