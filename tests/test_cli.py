"""The command line prints what the issues promise, with numbers a user can check."""

import pytest

from snapmem.reference import exact
from snapmem.cli import main


def parse(text):
    return dict(line.split(": ", 1) for line in text.strip().splitlines())


def test_equilibrium_balloon_prints_measures_and_report(capsys):
    assert main(["equilibrium", "balloon", "--set", "nodes=101", "--set", "E_hat=0.1538", "--pressure", "0.012"]) == 0
    out = parse(capsys.readouterr().out)
    for key in ("volume", "u_max", "stretch_max", "converged", "iterations", "residual_norm", "reason"):
        assert key in out
    assert out["converged"] == "True"
    lam = exact.balloon_stretch(0.012, E_hat=0.1538)
    assert float(out["stretch"]) == pytest.approx(lam, rel=2e-4)
    assert float(out["u_max"]) == pytest.approx(2 * 10 * (lam - 1), rel=2e-3)   # south pole fixed: north pole moves 2R(lam-1)


def test_scenes_lists_parameters_with_units(capsys):
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    assert "balloon:" in out and "torus:" in out and "plate:" in out
    assert "Rs = 2.0 [m]" in out and "nodes = 101" in out


class _Stream:
    """A text stream that says whether it is a terminal."""

    def __init__(self, tty):
        self.tty, self.parts = tty, []

    def isatty(self):
        return self.tty

    def write(self, text):
        self.parts.append(text)

    def flush(self):
        pass


@pytest.mark.parametrize("tty", [True, False])
def test_progress_redraws_on_a_terminal_and_writes_lines_to_a_file(tty):
    from snapmem.io.progress import Progress
    stream = _Stream(tty)
    display = Progress(stream=stream, interval=0.0, file_interval=0.0)
    display.show("step 1")
    display.show("step 2")
    display.close()
    assert "".join(stream.parts) == ("\rstep 1\033[K\rstep 2\033[K\n" if tty else "step 1\nstep 2\n")


def test_progress_shows_the_last_line_on_close_and_nothing_where_not_wanted():
    from snapmem.io.progress import Progress, bar, duration
    stream = _Stream(False)
    display = Progress(stream=stream, file_interval=1e9)           # no line is due before close
    display.show("a")
    display.show("b")
    display.close()
    assert stream.parts == ["b\n"]
    quiet = _Stream(False)
    display = Progress(stream=quiet, file_interval=None)           # a terminal-only display on a file
    display.show("a", force=True)
    display.close()
    assert quiet.parts == []
    assert bar(0.5, 4) == "##--" and bar(2.0, 3) == "###" and duration(3725) == "1h02m" and duration(61) == "1m01s"


def test_loads_needed_for_voltage_controls_and_parameters():
    from snapmem.catalog.loads import loads_needed
    assert loads_needed("voltage") == loads_needed("E_hat") == loads_needed("pressure", "E_hat") == ("voltage",)
    assert loads_needed("pressure") == loads_needed("volume", "aspect_ratio") == ()


@pytest.mark.parametrize("vary, words", [
    ("E_hat=0:1", ["--vary 'E_hat=0:1'", "NAME=START:STOP:COUNT", "NAME=v1,v2,..."]),
    ("E_hat=0:1:0", ["E_hat COUNT = 0", ">= 1"]),
    ("E_hat=0.1,soon", ["E_hat = 'soon'", "must be a number"]),
    ("E_hat", ["--vary 'E_hat'", "NAME=START:STOP:COUNT"]),
])
def test_fold_vary_errors_name_the_value_and_what_is_allowed(vary, words, capsys):
    assert main(["fold", "torus", "--vary", vary]) == 2
    err = capsys.readouterr().err
    assert all(w in err for w in words), err


@pytest.mark.parametrize("vary, control", [("E_hat", "voltage"), ("voltage", "E_hat"), ("pressure", "pressure")])
def test_fold_refuses_to_vary_the_load_its_control_sets(vary, control, capsys):
    """Failed on 489037c: ``fold --vary E_hat --control voltage`` wrote the same voltage limit for
    every E_hat (the control overrides the parameter), with no word of it."""
    assert main(["fold", "balloon", "--vary", f"{vary}=0.05,0.1", "--control", control]) == 2
    err = capsys.readouterr().err
    assert f"--vary {vary} with --control {control}" in err and "vary another parameter" in err, err


def test_fold_table_names_each_column_once(tmp_path):
    """Failed on 489037c: varying E_hat under pressure control wrote two E_hat columns (the varied
    value and the point's measure; pandas read the second back as 'E_hat.1')."""
    import pandas as pd
    from snapmem.reference.exact import balloon_limit_point
    out = tmp_path / "fold.csv"
    assert main(["fold", "balloon", "--set", "nodes=41", "--vary", "E_hat=0.05,0.1", "--out", str(out)]) == 0
    table = pd.read_csv(out)
    assert len(set(table.columns)) == len(table.columns) and "E_hat.1" not in table
    assert list(table["E_hat"]) == [0.05, 0.1]
    for e_hat, limit in zip(table["E_hat"], table["pressure_limit"]):
        assert limit == pytest.approx(balloon_limit_point(E_hat=e_hat)[1], rel=2e-3)


def test_vary_and_grid_share_one_parser():
    from snapmem.sweeps.grid import parse_axis
    assert parse_axis("E_hat=0:0.2:3", option="--vary", number=True) == ("E_hat", [0.0, 0.1, 0.2])
    assert parse_axis("nodes=5,7", option="--vary", number=True) == ("nodes", [5, 7])


def test_hysteresis_exit_code_follows_whether_the_loop_closed(monkeypatch, capsys):
    import pandas as pd
    from snapmem.continuation import hysteresis as module
    snaps = pd.DataFrame(columns=["event", "control_at_limit", "control_settled", "u_max_before", "u_max_after"])
    for closed, code in ((True, 0), (False, 1)):
        monkeypatch.setattr(module, "hysteresis", lambda scene, control, peak=None, closed=closed:
                            module.Hysteresis(pd.DataFrame(), snaps, "loop closed", closed=closed))
        assert main(["hysteresis", "balloon", "--set", "nodes=11"]) == code
    assert capsys.readouterr().out.count("status: loop closed") == 2


def test_the_command_exits_at_once_with_its_code_after_its_exit_handlers(tmp_path):
    """``snapmem`` (snapmem.cli.run) skips the interpreter's teardown: the exit code, the streams,
    the files written and the exit handlers must all be as a normal exit leaves them."""
    import subprocess
    import sys
    from pathlib import Path
    root = Path(__file__).resolve().parents[1]
    script = ("import atexit, sys\natexit.register(lambda: print('handler ran'))\n"
              "sys.argv = ['snapmem'] + sys.argv[1:]\nfrom snapmem.cli import run\nrun()\n")

    def snapmem(*args):
        return subprocess.run([sys.executable, "-c", script, *args], capture_output=True, text=True, cwd=tmp_path,
                              env={**__import__("os").environ, "PYTHONPATH": str(root)}, timeout=300)

    done = snapmem("trace", "balloon", "--set", "nodes=21", "--until", "stretch_max=2", "--out", "b.csv")
    assert done.returncode == 0 and done.stdout.rstrip().endswith("handler ran"), done.stderr
    import pandas as pd
    table = pd.read_csv(tmp_path / "b.csv")
    assert table["stretch_max"].iloc[-1] == pytest.approx(2.0, rel=1e-9) and (tmp_path / "b.npz").exists()
    bad = snapmem("trace", "balloon", "--set", "nodes=-3")
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "handler ran" in bad.stdout
