"""The row file of a sweep: one CSV line per finished design, and the metadata beside it.

The file is append-only while the sweep runs (each row flushed and fsynced at once), repaired
after a kill (a last line cut short is dropped), locked against a second sweep writing to it, and
rewritten in design order when every design is done. ``<out>.sweep.json`` keeps what the rows
depend on besides the design; resuming with a different one is refused.
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
    second sweep writing to it at the same time."""

    def __init__(self, path, names: list[str]):
        self.path = os.fspath(path)
        self.names = names
        self.outputs = None              # output column names, once the header is known
        self.done = {}                   # key -> design index of rows already in the file
        folder = os.path.dirname(os.path.abspath(self.path))
        if not os.path.isdir(folder):
            raise SnapmemError(f"out = {self.path!r}: folder {folder!r} does not exist")
        if os.path.isdir(self.path):
            raise SnapmemError(f"out = {self.path!r}: is a folder, must be a CSV file")
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
            raise

    def _read(self):
        data = b""
        while True:
            chunk = os.pread(self.fd, 1 << 20, len(data))
            if not chunk:
                break
            data += chunk
        if data and not data.endswith(b"\n"):         # a line cut short by a kill: drop it
            keep = data.rfind(b"\n") + 1
            log.warning("%s: dropped a partial last line (%d bytes) left by an interrupted sweep",
                        self.path, len(data) - keep)
            os.ftruncate(self.fd, keep)
            os.fsync(self.fd)
            data = data[:keep]
        if not data:
            return
        try:
            rows = list(csv.reader(io.StringIO(data.decode("utf-8"))))
        except (UnicodeDecodeError, csv.Error) as exc:
            raise SnapmemError(f"out = {self.path!r}: not a sweep CSV ({exc})") from None
        header = rows[0]
        head = [*LEADING, *self.names, "status"]
        if header[:len(head)] != head or header[-1:] != ["message"]:
            raise SnapmemError(f"out = {self.path!r}: has columns {', '.join(header)}; this sweep writes "
                               f"{', '.join(head)}, ..., message: resume with the same grid or choose a new file")
        self.outputs = header[len(head):-1]
        for line, row in enumerate(rows[1:], start=2):
            if len(row) != len(header):
                raise SnapmemError(f"out = {self.path!r}: line {line} has {len(row)} fields, the header "
                                   f"{len(header)}: the file is damaged; repair or remove that line")
            self.done.setdefault(row[1], row[0])

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
        with open(tmp, "w", newline="", encoding="utf-8") as f:
            csv.writer(f, lineterminator="\n").writerows(rows)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.path)
        _fsync_folder(self.path)

    def close(self):
        os.close(self.fd)


def _fsync_folder(path):
    try:
        fd = os.open(os.path.dirname(os.path.abspath(path)), os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def check_meta(path: str, meta: dict, fresh: bool):
    """Write ``meta`` beside a new sweep file; refuse to resume one whose meta differs."""
    side = os.path.splitext(path)[0] + ".sweep.json"
    if not fresh and os.path.exists(side):
        try:
            with open(side, encoding="utf-8") as f:
                old = json.load(f)
        except (OSError, ValueError):
            old = None
        if old is not None and old != meta:
            changed = sorted(k for k in set(old) | set(meta) if old.get(k) != meta.get(k))
            raise SnapmemError(f"out = {path!r}: was written with {', '.join(f'{k} = {old.get(k)!r}' for k in changed)}; "
                               f"this sweep has {', '.join(f'{k} = {meta.get(k)!r}' for k in changed)}: "
                               "resume with the same settings or choose a new file")
        if old is not None:
            return
    tmp = side + ".tmp"
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(meta, f, indent=1, sort_keys=True)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, side)


def read_rows(path):
    """A sweep's CSV as a pandas DataFrame (parameters and outputs typed, empty cells NaN)."""
    import pandas as pd
    return pd.read_csv(path, dtype={"key": str, "status": str, "message": str}, keep_default_na=False,
                       na_values=[""])
