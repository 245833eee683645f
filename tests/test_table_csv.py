"""Tables without pandas (snapmem.io.table): the CSV written from a branch's rows is, byte for
byte, what pandas' ``DataFrame(rows, columns).to_csv(path, index=False)`` writes; the branch's
tables are still DataFrames to the Python API, built once at the first read; and ``snapmem trace``
writing both its files imports no pandas."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings, strategies as st

from snapmem import build_scene
from snapmem.continuation import ContinuationOptions, trace
from snapmem.io.table import Rows, csv_cells, stored, write_csv

ROOT = Path(__file__).resolve().parents[1]


def both(tmp_path, rows, columns=None):
    """(this writer's bytes, pandas' bytes) for the same rows, and whether pandas was needed."""
    ours, theirs = tmp_path / "ours.csv", tmp_path / "pandas.csv"
    table = Rows(rows, columns)
    fast = csv_cells(table) is not None
    write_csv(table, ours)
    assert table._frame is None or not fast                  # written without building the DataFrame
    pd.DataFrame(rows, columns=columns).to_csv(theirs, index=False)
    return ours.read_bytes(), theirs.read_bytes(), fast


def same_as_pandas(tmp_path, table: Rows):
    ours, theirs, fast = both(tmp_path, table.rows, table._columns)
    assert fast, "a branch table fell back to pandas"
    assert ours == theirs


@pytest.fixture(scope="module")
def branches():
    """Real traces: the balloon (limit points and a rejected step), the torus (save_at points,
    no rejection), a plate stopped before any critical point (empty points table) and the two
    balloons on one volume (two membranes' columns, BPs)."""
    return {
        "balloon": trace(build_scene("balloon", nodes=51), "pressure", until={"stretch_max": 4.0}),
        "torus": trace(build_scene("torus", nodes=41), "pressure", until={"stretch_max": 1.5},
                       options=ContinuationOptions(save_at=(0.001, 0.002))),
        "plate": trace(build_scene("plate", nodes=21), "pressure", until={"stretch_max": 1.05}),
        "two_balloons": trace(build_scene("two_balloons", nodes=21), "volume", until={"stretch_max": 2.0}),
    }


@pytest.mark.parametrize("name", ["balloon", "torus", "plate", "two_balloons"])
def test_branch_tables_are_written_as_pandas_writes_them(tmp_path, branches, name):
    branch = branches[name]
    for which in ("table", "points", "rejections"):
        table = stored(branch, which)
        assert isinstance(table, Rows)
        same_as_pandas(tmp_path, table)


def test_the_traces_cover_points_rejections_and_empty_tables(branches):
    assert len(stored(branches["balloon"], "points")) >= 1 and len(stored(branches["balloon"], "rejections")) >= 1
    assert stored(branches["plate"], "points").empty and not stored(branches["plate"], "points").rows
    assert "SAVE" not in [r["point"] for _, r in stored(branches["torus"], "table").iterrows()]
    assert any(stored(branches["torus"], "table")["save_at"])
    assert "BP" in stored(branches["two_balloons"], "points")["kind"]


def test_branch_tables_are_dataframes_built_once():
    branch = trace(build_scene("balloon", nodes=21), "pressure", until={"stretch_max": 2.0})
    rows = stored(branch, "table")
    assert isinstance(rows, Rows)
    table = branch.table
    assert isinstance(table, pd.DataFrame) and branch.table is table and stored(branch, "table") is table
    pd.testing.assert_frame_equal(table, pd.DataFrame(rows.rows))
    table["extra"] = 1.0                                      # a change to it stays
    assert "extra" in branch.table
    assert isinstance(branch.points, pd.DataFrame) and isinstance(branch.rejections, pd.DataFrame)
    assert list(branch.rejections.columns) == ["step", "s", "ds", "reason"]
    branch.points = branch.points.assign(mark=True)           # the API may set a DataFrame
    assert stored(branch, "points") is branch.points and "mark" in branch.points


def test_the_summary_questions_match_the_dataframe():
    branch = trace(build_scene("balloon", nodes=21), "pressure", until={"stretch_max": 4.0})
    rows = stored(branch, "points")
    frame = branch.points
    assert len(rows) == len(frame) and rows.columns == list(frame.columns) and rows.empty == frame.empty
    for (_, a), (_, b) in zip(rows.iterrows(), frame.iterrows()):
        assert f"{a['control']:.10g} {a['u_max']:.6g} {a['located']}" == f"{b['control']:.10g} {b['u_max']:.6g} {b['located']}"


# ---- generated tables --------------------------------------------------------------------------

SPECIAL = [0.0, -0.0, np.nan, np.inf, -np.inf, 1e308, -1.7976931348623157e308, 5e-324, 2.2250738585072014e-308,
           1e16, 9999999999999998.0, 1e-4, 9.999999999999999e-05, 0.1, 1 / 3, 123456789012345680.0]
floats = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from(SPECIAL))
ints = st.one_of(st.integers(-2 ** 63, 2 ** 63 - 1), st.sampled_from([0, -1, 2 ** 53 + 1, 2 ** 63 - 1, -2 ** 63]))
texts = st.one_of(st.text(max_size=6), st.sampled_from(["", " ", "a,b", 'q"', "l\nm", "\r", "x\r\ny", "é", "None",
                                                         "nan", "1.0", "True"]))
python_values = st.one_of(floats, ints, st.booleans(), texts, st.none())
numpy_values = st.one_of(floats.map(np.float64), st.floats(width=32).map(np.float32), ints.map(np.int64),
                         st.booleans().map(np.bool_), st.integers(0, 2 ** 64 - 1).map(np.uint64))
families = {"float": floats, "int": ints, "bool": st.booleans(), "str": texts, "npfloat": floats.map(np.float64),
            "npint": ints.map(np.int64), "npbool": st.booleans().map(np.bool_), "float_int": st.one_of(floats, ints),
            "python": python_values}
names = st.one_of(st.sampled_from(["s", "control", "a,b", 'q"', "", "x y", "point"]), st.text(min_size=1, max_size=4))


@st.composite
def tables(draw, family_names=tuple(families), allow_other=False):
    """Rows of dicts: each column of one family (or anything), with None, NaN and missing keys
    sprinkled in, over 0 to 6 rows."""
    columns = draw(st.lists(names, max_size=5, unique=True))
    kinds = {c: draw(st.sampled_from(family_names)) for c in columns}
    n = draw(st.integers(0, 6))
    rows = []
    for _ in range(n):
        row = {}
        for c in columns:
            gap = draw(st.sampled_from(["value"] * 6 + ["None", "nan", "absent"]))
            if gap == "value":
                strategy = families[kinds[c]]
                if allow_other and draw(st.booleans()):
                    strategy = st.one_of(python_values, numpy_values)
                row[c] = draw(strategy)
            elif gap != "absent":
                row[c] = None if gap == "None" else np.nan
        rows.append(row)
    return rows


@settings(max_examples=400, deadline=None)
@given(tables(family_names=("float", "int", "bool", "str", "npfloat", "npint", "npbool", "float_int", "python")))
def test_generated_tables_written_as_pandas_writes_them(tmp_path_factory, rows):
    ours, theirs, fast = both(tmp_path_factory.mktemp("t"), rows)
    assert ours == theirs


@settings(max_examples=300, deadline=None)
@given(tables(family_names=("float", "int", "bool", "str", "float_int", "python")))
def test_python_values_take_the_fast_path(tmp_path_factory, rows):
    ours, theirs, fast = both(tmp_path_factory.mktemp("t"), rows)
    assert fast and ours == theirs


@settings(max_examples=300, deadline=None)
@given(tables(allow_other=True))
def test_any_mixture_is_written_as_pandas_writes_it(tmp_path_factory, rows):
    ours, theirs, fast = both(tmp_path_factory.mktemp("t"), rows)
    assert ours == theirs


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(ints, floats, floats, texts), max_size=4))
def test_sequences_with_named_columns(tmp_path_factory, rows):
    ours, theirs, fast = both(tmp_path_factory.mktemp("t"), rows, ["step", "s", "ds", "reason"])
    assert fast and ours == theirs


@pytest.mark.parametrize("rows, columns", [([], None), ([], ["a", "b"]), ([], ["only"]), ([{}], None),
                                           ([{}, {}], None), ([{"a": ""}], None), ([{"a": None}], None),
                                           ([{"a": 1}, {"b": 2.5}], None), ([{"a": 1, "b": 2}], ["b", "a"]),
                                           ([{"a": 1, "b": 2}], ["b", "c"]), ([{"a": 2 ** 63}], None),
                                           ([{"a": 2 ** 64}, {"a": 1.5}], None), ([{"a": [1]}], None),
                                           ([{"a": True}, {"a": 1}], None), ([{"a": "x"}, {"a": 1.5}], None)])
def test_edge_tables(tmp_path, rows, columns):
    ours, theirs, _ = both(tmp_path, rows, columns)
    assert ours == theirs


# ---- the command -------------------------------------------------------------------------------

CHECK = """
import sys, io, contextlib
from snapmem.cli import main
with contextlib.redirect_stdout(io.StringIO()) as out:
    main(['trace', 'balloon', '--set', 'nodes=21', '--until', 'stretch_max=4', '--out', {out!r}, '--points', {points!r}])
assert 'LP: pressure' in out.getvalue(), out.getvalue()
print(" ".join(m for m in ("numba", "pandas") if m in sys.modules) or "none")
"""


def test_a_trace_writing_its_tables_imports_no_pandas(tmp_path):
    out, points = tmp_path / "b.csv", tmp_path / "p.csv"
    # this process's environment but snapmem's own settings: OPENBLAS_CORETYPE and the like choose
    # the BLAS kernels, whose rounding the CSV's last digits show
    environment = {k: v for k, v in os.environ.items() if not k.startswith("SNAPMEM_")}
    done = subprocess.run([sys.executable, "-c", CHECK.format(out=str(out), points=str(points))], capture_output=True,
                          text=True, cwd=ROOT, env={**environment, "PYTHONPATH": str(ROOT), "SNAPMEM_COLD": "compile"},
                          timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "numba"
    branch = trace(build_scene("balloon", nodes=21), "pressure", until={"stretch_max": 4.0})
    assert out.read_text() == branch.table.to_csv(index=False)
    assert points.read_text() == branch.points.to_csv(index=False)
