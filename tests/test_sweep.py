"""Sweeps lose no work: killed with SIGKILL twice and resumed, a sweep writes exactly the rows of an
uninterrupted run; a Dask local cluster writes the same rows as the local pool; failed designs are
rows with their status."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from snapmem import SnapmemError
from snapmem.cli import main
from snapmem.sweeps.sweep import Progress, design_key, parse_axis, read_rows, sweep

ROOT = Path(__file__).resolve().parents[1]
# 200 cheap designs of the real equilibrium job: balloon pressures below its limit point, 2 voltages
GRID = ["balloon", "--grid", "pressure=0.001:0.012:100", "--grid", "E_hat=0,0.1", "--set", "nodes=9"]


def snapmem_sweep(out, *extra):
    """The CLI in a subprocess (so that it can be killed), as a user runs it."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.Popen([sys.executable, "-m", "snapmem.cli", "sweep", *GRID, "--out", str(out),
                             "--workers", "2", "--quiet", *extra],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def rows_in(path):
    return path.read_bytes().count(b"\n") - 1 if path.exists() else 0


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep") / "whole.csv"
    run = snapmem_sweep(out)
    stdout, stderr = run.communicate(timeout=120)
    assert run.returncode == 0, stderr
    assert "200 rows; converged 200" in stdout
    return out.read_bytes(), Path(str(out) + ".sweep.json").read_bytes()


def journal(out, rows: bytes, uninterrupted):
    """Write a journal's rows and its metadata file (the grid and settings it was made with)."""
    out.write_bytes(rows)
    Path(str(out) + ".sweep.json").write_bytes(uninterrupted[1])


def kill_after(out, rows):
    """Start the sweep on ``out`` and SIGKILL it once it has written at least ``rows`` rows."""
    run = snapmem_sweep(out)
    deadline = time.monotonic() + 60
    while rows_in(out) < rows and run.poll() is None and time.monotonic() < deadline:
        time.sleep(0.002)
    os.kill(run.pid, signal.SIGKILL)
    run.communicate()
    assert run.returncode == -signal.SIGKILL, "the sweep finished before it could be killed"
    return rows_in(out)


@pytest.mark.slow                     # ~10 s: run by .ci/run with -m slow
def test_killed_twice_and_resumed_gives_the_rows_of_an_uninterrupted_run(tmp_path, uninterrupted):
    out = tmp_path / "rows.csv"
    first = kill_after(out, 30)
    second = kill_after(out, first + 60)
    assert 30 <= first < second < 200
    run = snapmem_sweep(out)
    stdout, stderr = run.communicate(timeout=120)
    assert run.returncode == 0, stderr
    assert out.read_bytes() == uninterrupted[0]        # same rows, same order, same bytes


def test_sigterm_stops_a_sweep_as_ctrl_c_does_and_the_rerun_completes_it(tmp_path, uninterrupted):
    """SIGTERM (kill PID) ends a sweep as Ctrl-C does: exit 130, the rows so far kept, no temporary
    file; the same command resumes it to the bytes of an uninterrupted run (on ed30f81 SIGTERM
    ended it with no cleanup, exit -15)."""
    out = tmp_path / "rows.csv"
    run = snapmem_sweep(out)
    deadline = time.monotonic() + 60
    while rows_in(out) < 20 and run.poll() is None and time.monotonic() < deadline:
        time.sleep(0.002)
    run.send_signal(signal.SIGTERM)
    _, stderr = run.communicate(timeout=60)
    assert run.returncode == 130 and "interrupted" in stderr, stderr
    assert 20 <= rows_in(out) < 200
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rows.csv", "rows.csv.sweep.json"]
    run = snapmem_sweep(out)
    run.communicate(timeout=120)
    assert run.returncode == 0 and out.read_bytes() == uninterrupted[0]


def test_a_line_cut_short_by_a_kill_is_dropped_and_rerun(tmp_path, uninterrupted):
    out = tmp_path / "rows.csv"
    lines = uninterrupted[0].split(b"\n")
    journal(out, b"\n".join(lines[:120]) + b"\n" + lines[120][:17], uninterrupted)     # 119 rows and a partial one
    run = snapmem_sweep(out)
    run.communicate(timeout=120)
    assert run.returncode == 0
    assert out.read_bytes() == uninterrupted[0]


def test_a_finished_sweep_reruns_nothing(tmp_path, uninterrupted):
    out = tmp_path / "rows.csv"
    journal(out, uninterrupted[0], uninterrupted)
    t0 = time.monotonic()
    assert main(["sweep", *GRID, "--out", str(out), "--quiet"]) == 0
    assert out.read_bytes() == uninterrupted[0]
    assert time.monotonic() - t0 < 5


@pytest.mark.slow                     # ~10 s: run by .ci/run with -m slow
def test_dask_local_cluster_gives_the_rows_of_the_local_pool(tmp_path, uninterrupted):
    pytest.importorskip("distributed", reason="dask[distributed] is not installed (pip install -e '.[dask]')")
    out = tmp_path / "dask.csv"
    run = snapmem_sweep(out, "--scheduler", "local")
    stdout, stderr = run.communicate(timeout=180)
    assert run.returncode == 0, stderr
    assert out.read_bytes() == uninterrupted[0]


def designs_that_fail(design):
    k = design["k"]
    if k == 1:
        raise SnapmemError("c1 = -1: must be > 0")
    if k == 2:
        raise ZeroDivisionError("boom\non two lines")
    if k == 3:
        time.sleep(60)
    if k == 4:
        os._exit(3)
    if k == 5:
        return {"y": float("nan"), "z": 'a,b "quoted"'}
    return {"y": k / 8, "z": "fine"}


def test_failed_designs_are_rows_with_status_and_message(tmp_path):
    out = tmp_path / "fail.csv"
    t0 = time.monotonic()
    table = sweep(designs_that_fail, {"k": list(range(8))}, out, workers=2, timeout=1.0, progress=False)
    assert time.monotonic() - t0 < 20
    status = dict(zip(table["k"], table["status"]))
    assert status == {0: "ok", 1: "invalid", 2: "error", 3: "timeout", 4: "crashed", 5: "ok", 6: "ok", 7: "ok"}
    message = dict(zip(table["k"], table["message"]))
    assert message[1] == "c1 = -1: must be > 0"
    assert message[2] == "ZeroDivisionError: boom on two lines"
    assert message[3] == "killed after the time limit of 1 s"
    assert message[4] == "the process running the design died (exit code 3)"
    assert table["y"].isna().tolist() == [False, True, True, True, True, True, False, False]   # NaN: empty cell
    assert table.loc[5, "z"] == 'a,b "quoted"' and table.loc[7, "y"] == 7 / 8
    assert list(table.columns) == ["design", "key", "k", "status", "y", "z", "message"]
    assert table.loc[3, "key"] == design_key({"k": 3})


def test_resume_refuses_a_different_grid(tmp_path):
    out = tmp_path / "a.csv"
    sweep(lambda d: {"y": d["a"]}, {"a": [1, 2]}, out, workers=1, progress=False)
    with pytest.raises(SnapmemError, match="has columns design, key, a, status"):
        sweep(lambda d: {"y": d["b"]}, {"b": [1, 2]}, out, workers=1, progress=False)


@pytest.mark.parametrize("kwargs,words", [
    ({"grid": {}}, "grid: has no designs"),
    ({"grid": [{"a": 1}, {"b": 2}]}, "every design needs the same names"),
    ({"grid": [{"a": 1}, {"a": 1}]}, "designs 0 and 1 are the same"),
    ({"grid": {"a": [float("nan")]}}, "a = nan: must be finite"),
    ({"grid": {"status": [1]}}, "reserved"),
    ({"grid": {"a": 3}}, "grid axis 'a' = 3: must be a list"),
    ({"workers": 0}, "workers = 0: must be an integer >= 1"),
    ({"timeout": -1}, "timeout = -1.0: must be > 0"),
    ({"scheduler": "udp://x"}, "scheduler = 'udp://x': must be 'local' or 'tcp://HOST:PORT'"),
    ({"out": "/no/such/folder/x.csv"}, "folder '/no/such/folder' does not exist"),
])
def test_bad_sweep_arguments(tmp_path, kwargs, words):
    args = {"grid": {"a": [1, 2]}, "out": tmp_path / "x.csv", **kwargs}
    with pytest.raises(SnapmemError) as info:
        sweep(lambda d: {}, progress=False, **args)
    assert words in str(info.value)


def test_parse_axis():
    assert parse_axis("pressure=0:1:3") == ("pressure", [0.0, 0.5, 1.0])
    assert parse_axis("material=gent,neo_hookean") == ("material", ["gent", "neo_hookean"])
    assert parse_axis("nodes=5,7") == ("nodes", [5, 7])
    for bad in ("pressure", "pressure=", "pressure=0:1", "pressure=0:1:x", "p=a:1:3", "p=1,,2", "p=0:1:0"):
        with pytest.raises(SnapmemError):
            parse_axis(bad)


def test_progress_shows_rate_and_time_left():
    bar = Progress(10, 2, enabled=False)
    time.sleep(0.01)
    for status in ("ok", "timeout"):
        bar.update(status)
    text = bar.text()
    assert text.startswith("sweep 4/10 [#########") and "designs/s" in text and "left" in text
    assert "1 timeout" in text


def readme_block(start):
    """The README's fenced code block whose first line starts with ``start``."""
    text = (ROOT / "README.md").read_text()
    for block in text.split("```")[1::2]:
        body = block.split("\n", 1)[1]
        if body.lstrip().startswith(start):
            return body
    raise AssertionError(f"no README block starts with {start!r}")


def test_readme_sweep_command(tmp_path, monkeypatch, capsys):
    from snapmem.reference import exact
    import shlex
    monkeypatch.chdir(tmp_path)
    argv = shlex.split(readme_block("snapmem sweep").strip())
    assert main([*argv[1:], "--quiet"]) == 0
    table = read_rows(tmp_path / "rows.csv")
    assert len(table) == 6 and set(table["status"]) == {"converged"}
    row = table[(table["pressure"] == 0.012) & (table["E_hat"] == 0.1538)].iloc[0]
    assert row["stretch"] == pytest.approx(exact.balloon_stretch(0.012, E_hat=0.1538), rel=1e-3)
    assert "rows.csv: 6 rows; converged 6" in capsys.readouterr().out


def test_readme_sweep_python(tmp_path):
    code = readme_block("from snapmem.sweeps.sweep")
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    run = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    table = read_rows(tmp_path / "rows.csv")
    assert len(table) == 6 and set(table["status"]) == {"converged"}
    assert table["stretch"].between(1.0, 1.6).all()


@pytest.mark.slow
def test_soak_study_runs_on_a_few_designs(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    run = subprocess.run([sys.executable, str(ROOT / "studies" / "soak.py"), "--count", "12", "--workers", "2",
                          "--timeout", "60", "--out", str(tmp_path / "soak.csv")],
                         env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    table = read_rows(tmp_path / "soak.csv")
    assert len(table) == 12 and table["i"].tolist() == list(range(12))
    assert run.stdout.strip().startswith("12 rows:")
    assert set(table["status"]) <= {"converged", "no_equilibrium", "max_iterations", "step_too_small",
                                    "left_domain", "singular", "not_finite", "failed", "invalid", "error", "timeout"}


def test_resume_refuses_other_fixed_parameters(tmp_path, capsys):
    out = tmp_path / "rows.csv"
    args = ["sweep", "balloon", "--grid", "pressure=0.004,0.008", "--out", str(out), "--quiet", "--workers", "1"]
    assert main([*args, "--set", "nodes=11"]) == 0
    assert main([*args, "--set", "nodes=13"]) == 2
    err = capsys.readouterr().err
    assert "was written with fixed = {'nodes': '11'}" in err and "{'nodes': '13'}" in err
    assert main([*args, "--set", "nodes=11"]) == 0                    # the same settings resume


def test_a_journal_of_an_older_snapmem_resumes_with_its_rows_checked(tmp_path):
    """Before the grid was recorded the metadata lived in ``r.sweep.json`` (shared by r.csv and r):
    such a journal resumes, each of its rows checked against the grid, and gets its own file."""
    import json
    out = tmp_path / "r.csv"
    first = sweep(lambda d: {"y": 2 * d["a"]}, {"a": [1, 2]}, out, workers=1, progress=False)
    meta = json.loads(Path(str(out) + ".sweep.json").read_text())
    Path(str(out) + ".sweep.json").unlink()
    (tmp_path / "r.sweep.json").write_text(json.dumps({k: v for k, v in meta.items() if k != "grid"}))
    lines = out.read_bytes().split(b"\n")
    out.write_bytes(b"\n".join(lines[:2]) + b"\n")                   # design 1 still to run
    table = sweep(lambda d: {"y": 2 * d["a"]}, {"a": [1, 2]}, out, workers=1, progress=False,
                  meta={k: v for k, v in meta.items() if k != "grid"})
    assert table.equals(first)
    assert json.loads(Path(str(out) + ".sweep.json").read_text())["grid"]["keys"] == meta["grid"]["keys"]
