"""Tables without pandas: rows that become a DataFrame on first use, and their CSV.

A command that only writes its tables and prints a summary (``snapmem trace``) need not import
pandas (about 0.2 s of the process). :class:`Rows` holds what ``pandas.DataFrame(rows,
columns=columns)`` is built from, and builds that DataFrame the first time it is asked for it
(:meth:`Rows.frame`; :class:`FrameField` does it for an attribute). :func:`write_csv` writes the
bytes ``DataFrame(rows, columns).to_csv(path, index=False)`` writes, without building it.

Which cells it writes as pandas does (``tests/test_table_csv.py`` compares the two on traces
and on generated tables): Python floats, ints and bools, their numpy float64, int64 and bool_,
str, None and NaN. A column
is typed as pandas types it: ints and floats (NaN or None among them) are float64 and written as
numpy prints a float64; ints alone are ints; bools alone are bools; str with missing values is
str; anything else mixed is an object column, its cells written by the csv module. A table with
a value of another type (or an int beyond int64) is written by pandas itself.
"""

from __future__ import annotations

import csv
from typing import Iterable, Sequence

import numpy as np

_FLOATS = (float, np.float64)              # float32 alone stays float32 in pandas: left to pandas
_INTS = (int, np.int64)
_BOOLS = (bool, np.bool_)
_INT64 = (-2 ** 63, 2 ** 63 - 1)
_PYTHON = (float, int, bool, str)          # the cells an object column writes as the csv module does


class Rows:
    """The rows of a table (dicts, or sequences when ``columns`` names them) and the DataFrame
    they make, ``pandas.DataFrame(rows, columns=columns)``, built at the first :meth:`frame`.

    It answers the questions a summary asks without building it: ``len``, :attr:`empty`,
    :attr:`columns`, :meth:`iterrows` (index and a dict per row) and a column by ``table[name]``.
    """

    def __init__(self, rows: Sequence, columns: Sequence[str] | None = None):
        self.rows = list(rows)
        self._columns = None if columns is None else list(columns)
        self._frame = None

    @property
    def columns(self) -> list:
        """The column names in the DataFrame's order (first appearance, when not given)."""
        if self._columns is not None:
            return list(self._columns)
        seen = {}
        for row in self.rows:
            seen.update(dict.fromkeys(row))
        return list(seen)

    def __len__(self) -> int:
        return len(self.rows)

    @property
    def empty(self) -> bool:
        return not self.rows or not self.columns

    def records(self) -> list[dict]:
        """Each row as a dict over every column (None where a row has no value)."""
        columns = self.columns
        if self.rows and not isinstance(self.rows[0], dict):
            return [dict(zip(columns, row)) for row in self.rows]
        return [{c: row.get(c) for c in columns} for row in self.rows]

    def iterrows(self):
        return enumerate(self.records())

    def __getitem__(self, column: str) -> list:
        if column not in self.columns:
            raise KeyError(column)
        return [row[column] for row in self.records()]

    def __contains__(self, column) -> bool:
        return column in self.columns

    def frame(self):
        """The pandas DataFrame of these rows (imports pandas; built once)."""
        if self._frame is None:
            import pandas as pd
            self._frame = pd.DataFrame(self.rows, columns=self._columns)
        return self._frame


class FrameField:
    """A dataclass field that holds a DataFrame or :class:`Rows`, and gives a DataFrame: the
    rows' frame, built at the first read and kept (so changes to it stay). :func:`stored` reads
    what it holds without building anything."""

    def __set_name__(self, owner, name):
        self.slot = "_" + name

    def __get__(self, obj, owner=None):
        if obj is None:
            raise AttributeError(self.slot[1:])        # a dataclass field without a default
        value = obj.__dict__[self.slot]
        if isinstance(value, Rows):
            value = obj.__dict__[self.slot] = value.frame()
        return value

    def __set__(self, obj, value):
        obj.__dict__[self.slot] = value


def stored(obj, name: str):
    """What the :class:`FrameField` ``name`` of ``obj`` holds: its :class:`Rows` until a read
    built the DataFrame, the DataFrame after."""
    return obj.__dict__["_" + name]


def write_csv(table, path) -> None:
    """``table`` (a DataFrame or :class:`Rows`) as CSV at ``path``: the bytes of pandas'
    ``to_csv(path, index=False)``."""
    if isinstance(table, Rows) and table._frame is None:
        cells = csv_cells(table)
        if cells is not None:
            with open(path, "w", encoding="utf-8", newline="") as handle:
                writer = csv.writer(handle, lineterminator="\n", delimiter=",", quoting=csv.QUOTE_MINIMAL,
                                    doublequote=True, escapechar=None, quotechar='"')
                writer.writerow(cells[0])
                writer.writerows(zip(*cells[1:]) if cells[0] else ([] for _ in table.rows))   # no columns: empty lines
            return
    frame = table.frame() if isinstance(table, Rows) else table
    frame.to_csv(path, index=False)


def csv_cells(table: Rows) -> list | None:
    """[header, column 1's cells, column 2's cells, ...] as pandas hands them to the csv module;
    None if a column holds a value this writer does not type as pandas does."""
    columns = table.columns
    if not all(type(c) is str for c in columns) or len(set(columns)) < len(columns):
        return None
    records = table.records() if table.rows else []
    out = [columns]
    for c in columns:
        cells = _column_cells([row[c] for row in records])
        if cells is None:
            return None
        out.append(cells)
    return out


def _kind(v) -> str | None:
    """'missing', 'float', 'int', 'bool' or 'str' (None: a value this writer leaves to pandas)."""
    t = type(v)
    if v is None:
        return "missing"
    if t in _FLOATS:
        return "nan" if v != v else "float"
    if t in _BOOLS:
        return "bool"
    if t in _INTS:
        return "int" if _INT64[0] <= int(v) <= _INT64[1] else None
    if t is str:
        return "str"
    return None


def _column_cells(values: list) -> list | None:
    types = set(map(type, values))
    if types and types <= {float, np.float64}:           # the common columns, at once
        numbers = np.array(values, dtype=np.float64)
        return [("" if s == "nan" else s) for s in numbers.astype(str).tolist()]
    if types and types <= {bool, np.bool_}:
        return ["True" if v else "False" for v in values]
    if types == {str}:
        return values
    kinds = [_kind(v) for v in values]
    if None in kinds:
        return None
    present = set(kinds) - {"missing", "nan"}
    if not present:                                      # nothing but None and NaN (or no rows)
        return [""] * len(values)
    if present <= {"float", "int"} and ("float" in present or "nan" in kinds or "missing" in kinds):
        numbers = np.array([np.nan if k in ("missing", "nan") else v for k, v in zip(kinds, values)], dtype=np.float64)
        text = numbers.astype(str).tolist()             # float64 as pandas writes it: numpy's str
        return ["" if k in ("missing", "nan") else s for k, s in zip(kinds, text)]
    if present == {"int"}:
        return [str(int(v)) for v in values]
    if present == {"bool"}:
        return [("True" if v else "False") if k == "bool" else "" for k, v in zip(kinds, values)]
    if present == {"str"}:
        return [v if k == "str" else "" for k, v in zip(kinds, values)]
    # an object column (bools with numbers or strings, ...): the csv module writes each cell
    if not all(type(v) in _PYTHON or k in ("missing", "nan") for k, v in zip(kinds, values)):
        return None                                      # numpy scalars in an object column: pandas' way
    return ["" if k in ("missing", "nan") else v for k, v in zip(kinds, values)]
