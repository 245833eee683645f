"""Result files: CSV tables that pandas reads back, with the parameters beside them as JSON."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import snapmem._lazy as _lazy

pd = _lazy.module("pandas")  # imported at first use (start-up)

from snapmem._version import __version__
from snapmem.io.table import write_csv


def fsync_folder(folder) -> None:
    """Flush a folder's entries to disk (after a rename into it), where the system allows."""
    try:
        fd = os.open(os.path.abspath(folder), os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_table(table: pd.DataFrame, path, meta: dict | None = None) -> Path:
    """Write ``table`` to CSV at ``path`` and ``meta`` to the JSON sidecar ``path`` + '.json'.

    ``table`` is a DataFrame or :class:`~snapmem.io.table.Rows` (written without pandas, the same
    bytes as its DataFrame's ``to_csv(path, index=False)``).

    Written to a temporary file and renamed, so an interrupted run never leaves half a file.
    """
    path = Path(path)
    if path.parent and not path.parent.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    try:
        write_csv(table, tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)                    # only left if the write did not finish
    if meta is not None:
        write_json(meta, sidecar(path))
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



def write_json(meta: dict, path) -> Path:
    """Write ``meta`` (with the snapmem version) as JSON at ``path``, atomically."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    try:
        tmp.write_text(json.dumps({"snapmem": __version__, **meta}, indent=2, default=str))
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def sidecar(path) -> Path:
    """The JSON file of parameters that :func:`write_table` writes beside the table ``path``."""
    path = Path(path)
    return path.with_name(path.name + ".json")


def distinct_outputs(outputs: dict) -> None:
    """SnapmemError if two of one command's output files are the same file.

    Parameters
    ----------
    outputs : dict
        What writes the file (e.g. '--out', "--out's parameters") -> list of paths (None and ''
        are skipped: an output not asked for).
    """
    from snapmem.errors import SnapmemError
    seen = {}
    for option, paths in outputs.items():
        for path in paths:
            if not path:
                continue
            real = os.path.realpath(os.fspath(path))
            if real in seen:
                first, name = seen[real]
                what = f"{first} and {option}" if first != option else option
                raise SnapmemError(f"{what}: both write the same file {os.fspath(path)!r}; give each output its own name")
            seen[real] = (option, os.fspath(path))


class OutputSet:
    """The files of one result, written as a set: all of them appear, or none.

    Each file is written under a staging name beside its final one (``x.csv`` -> ``x.csv.tmp.csv``,
    same suffix, so that writers that go by it still work); when the block ends without an error
    every staged file is renamed into place; on an error every staged file is removed. SIGINT and
    SIGTERM during the block wait until the set is in place, then raise ``KeyboardInterrupt``
    (a second signal aborts the set at once, leaving nothing).

    Examples
    --------
    >>> with OutputSet() as outputs:                                       # doctest: +SKIP
    ...     outputs.table(branch.table, "b.csv", meta)
    ...     branch.save(outputs.stage("b.npz"))
    """

    def __init__(self):
        self.staged: list[tuple[Path, Path]] = []
        self._held = None

    def stage(self, path) -> Path:
        """The staging name to write the final file ``path`` under (created by the caller)."""
        final = Path(path)
        staged = final.with_name(f"{final.name}.tmp{final.suffix}")
        self.staged.append((staged, final))
        return staged

    def table(self, table: pd.DataFrame, path, meta: dict | None = None) -> Path:
        """``table`` (a DataFrame or :class:`~snapmem.io.table.Rows`) as CSV at ``path``, and ``meta`` at its sidecar ``path.json`` if given."""
        write_table(table, self.stage(path))
        if meta is not None:
            write_json(meta, self.stage(sidecar(path)))
        return Path(path)

    def npz(self, path, **arrays) -> Path:
        """``arrays`` as a compressed .npz at ``path`` (which must end in .npz)."""
        write_npz(self.stage(path), **arrays)
        return Path(path)

    def __enter__(self) -> "OutputSet":
        from snapmem.io.interrupts import HeldInterrupts
        self._held = HeldInterrupts().__enter__()
        return self

    def __exit__(self, kind, value, traceback) -> bool:
        try:
            if kind is None:
                self._commit()
        finally:
            for staged, _ in self.staged:
                staged.unlink(missing_ok=True)            # only left when the set was not committed
            self._held.__exit__(kind, value, traceback)
        if kind is None and self._held.received is not None:
            raise KeyboardInterrupt                        # taken now that the set is whole
        return False

    def _commit(self):
        for staged, final in self.staged:
            if not staged.exists():
                raise FileNotFoundError(f"{final}: its writer wrote nothing")
        for staged, final in self.staged:
            os.replace(staged, final)
        for folder in {os.path.dirname(os.path.abspath(final)) for _, final in self.staged}:
            fsync_folder(folder)
