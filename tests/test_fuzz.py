"""Fuzz the command line with odd values: every scene parameter (``--set`` / ``--grid NAME=VALUE``)
and every numeric or path option of every command gets 0, -1, +-inf, nan, 1e308, 1e-308, '1_0',
full-width digits '１２', an empty string and the like.

The contract checked, exactly: no traceback ever; the exit code is 0 (done) or 2 (bad input); exit
2 prints exactly one line on stderr, ``snapmem: error: ...``; exit 0 prints nothing on stderr (no
warnings either). There is no exit-1 escape hatch, so the commands are chosen where a well-formed
input cannot legitimately end in exit 1 (a solver or target failure, see the README's exit codes):

- Scene parameters go through ``sweep`` (one design, ``--grid NAME=VALUE``), whose exit codes are 0
  and 2 only: a design the solver cannot solve is a row with its status (``no_equilibrium``), so an
  odd value is either refused up front (exit 2) or solved or not as a result (exit 0). Through
  ``equilibrium`` or ``simulate`` a well-formed but extreme value (E_hat = 3, a pressure past the
  limit point, eps = 2.5 in the pump, a 2.5 m barrier width in the gripper) legitimately has no
  equilibrium or ends the run early: exit 1. A sweep row with status ``error`` or ``crashed`` (an
  exception in the job) counts as a traceback; one that ran past the sweep's 3 s limit is a
  ``timeout`` row, a result.
- Options of solving commands are fuzzed with a target the run can reach: ``trace`` stops at
  ``stretch = 1.3`` (reached in 20 steps) or, when ``--until`` itself is fuzzed, at the first
  limit point; ``--max-steps``, ``equilibrium --pressure`` and ``hysteresis --peak`` get, besides
  the values that must be refused, reachable values written oddly (``1_00``, full-width digits):
  a step budget too small for the target, a pressure past the limit point or a peak the branch
  cannot reach in its steps is a target failure, exit 1 by design. A peak at or below the control
  the snap settled at cannot be honoured and is refused (exit 2).

The CLI runs in-process (:func:`snapmem.cli.main` with captured output), on small scenes and short
runs so that an accepted odd value stays cheap; each example runs in the fixture's folder and the
files it wrote are removed after it, so no example sees another's outputs (a second sweep into the
same CSV would be refused as another grid).
"""

import contextlib
import csv
import io
import shutil
import warnings
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from snapmem.catalog.scenes import SCENES
from snapmem.cli import main

#: Values that are not numbers, not finite or out of every parameter's bounds, or odd spellings.
ODD = ["0", "-1", "inf", "-inf", "nan", "1e308", "-1e308", "1e-308", "1_0", "１２", "", " ", "0x10", "1e", "--",
       "2.5", "3"]
#: The odd values of an option whose well-formed numbers can all be a legitimate target failure:
#: those that must be refused, and reachable values written oddly.
REFUSED = ["inf", "-inf", "nan", "1e308", "-1e308", "", " ", "0x10", "1e", "--"]
REACHABLE = {"--max-steps": ["0", "-1", "1e-308", "2.5", "1_00", "１００", "100"],
             "--pressure": ["0", "-1", "1e-308", "1_0", "0.0_1", "０.０１", "0.01"],
             "--peak": ["0", "-1", "1e-308", "0.0_3", "０.０３", "0.03"]}
SMALL = ["--set", "nodes=7"]
#: A sweep of one design in this folder, one worker, no progress bar, and a time limit: a design
#: whose solve is slow to fail (E_hat = 3 on the gripper tries every barrier widening, ~20 s) is a
#: ``timeout`` row, a result (exit 0), and the default suite stays fast.
SWEEP = ["--out", "s.csv", "--workers", "1", "--quiet", "--timeout", "3"]
#: Sweep rows that mean an exception in the job: a traceback a user would not see.
CRASHED = ("error", "crashed")


def run(argv):
    """(exit code, stdout, stderr) of ``snapmem argv`` run in-process."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        try:
            code = main(argv)
        except SystemExit as exc:            # argparse --help or a stray exit
            code = exc.code
    printed = "".join(f"{w.category.__name__}: {w.message}\n" for w in seen)     # what a user's terminal shows
    return code, out.getvalue(), err.getvalue() + printed


def problem(argv) -> str | None:
    """What is wrong with how the CLI answered ``argv`` (None: a result, or one line and exit 2)."""
    code, out, err = run(argv)
    if "Traceback" in out + err:
        return f"{argv}: traceback: {err}"
    if code not in (0, 2):
        return f"{argv}: exit {code}: {(out + err).strip()[-300:]}"
    lines = err.strip().splitlines()
    if code == 2 and not (len(lines) == 1 and lines[0].startswith("snapmem: error: ")):
        return f"{argv}: exit 2 without exactly one error line: {err!r}"
    if code != 2 and lines:
        return f"{argv}: exit {code} with stderr: {err!r}"
    if code == 0 and argv[0] == "sweep":
        with open("s.csv", newline="", encoding="utf-8") as f:
            rows = [row for row in csv.DictReader(f)]
        crashed = [row for row in rows if row.get("status") in CRASHED]
        if crashed:
            return f"{argv}: a design raised: {crashed[0].get('message')!r}"
    return None


def scene_parameter_commands(draw):
    """``sweep SCENE --grid NAME=VALUE`` for any scene's parameter (a sweep's exits are 0 and 2)."""
    scene = draw(st.sampled_from(sorted(SCENES)))
    name = draw(st.sampled_from([p.name for p in SCENES[scene].parameters]))
    value = draw(st.sampled_from(ODD))
    return ["sweep", scene, "--grid", f"{name}={value}"] + ([] if name == "nodes" else SMALL) + SWEEP


#: Trace balloon to a target reached in 20 steps.
TRACE = ["trace", "balloon", "--set", "nodes=11", "--max-steps", "20", "--until", "stretch=1.3"]
#: Simulate the balloon for 2 ms.
SIMULATE = ["simulate", "balloon", "--set", "nodes=11", "--t-end", "0.002", "--quiet"]

#: (command line before the option, option) for every numeric or path option.
OPTIONS = [
    (["equilibrium", "balloon", "--set", "nodes=11"], "--pressure"),
    (TRACE, "--save-at"),
    (["trace", "balloon", "--set", "nodes=11", "--until", "stretch=1.3"], "--max-steps"),
    (["trace", "balloon", "--set", "nodes=11", "--max-steps", "200", "--stop-at-first-limit"], "--until"),
    (TRACE, "--out"),
    (TRACE, "--points"),
    (TRACE, "--plot"),
    (TRACE + ["--restart", "branch.npz"], "--start-index"),
    (["fold", "plate", "--set", "nodes=11"], "--vary"),
    (["hysteresis", "balloon", "--set", "nodes=11"], "--peak"),
    (SIMULATE, "--tol"),
    (["simulate", "balloon", "--set", "nodes=11", "--quiet"], "--t-end"),
    (SIMULATE, "--frames"),
    (SIMULATE, "--out"),
    (["replay", "traj.npz", "--out", "a.gif", "--frames", "2"], "--fps"),
    (["replay", "traj.npz", "--out", "a.gif"], "--frames"),
    (["replay", "traj.npz", "--frames", "2"], "--out"),
    (["sweep", "balloon", "--set", "nodes=11", "--out", "s.csv", "--quiet", "--workers", "1"], "--grid"),
    (["sweep", "balloon", "--set", "nodes=11", "--grid", "pressure=0.01", "--out", "s.csv", "--quiet"], "--workers"),
    (["sweep", "balloon", "--set", "nodes=11", "--grid", "pressure=0.01", "--out", "s.csv", "--quiet",
      "--workers", "1"], "--timeout"),
]

#: How an option's odd value is typed: NAME=VALUE options get a name.
PREFIX = {"--until": "stretch=", "--vary": "H=", "--grid": "pressure="}


def option_commands(draw):
    base, option = draw(st.sampled_from(OPTIONS))
    odd = REFUSED + REACHABLE[option] if option in REACHABLE else ODD
    value = draw(st.sampled_from(odd + ["nodir/x.csv", ".", "x.csv", "x.png", "x.gif"]))
    return base + [option, PREFIX.get(option, "") + value]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A saved branch and trajectory to restart from and replay, in a folder of their own."""
    folder = tmp_path_factory.mktemp("fuzz")
    with contextlib.chdir(folder):
        assert run(["trace", "balloon", "--set", "nodes=11", "--max-steps", "20", "--until", "stretch=1.3",
                    "--out", "branch.csv"])[0] == 0
        assert run(["simulate", "balloon", "--set", "nodes=11", "--t-end", "0.002", "--quiet",
                    "--out", "traj.npz"])[0] == 0
    return folder


def fuzz(files, argv) -> str | None:
    """``problem(argv)`` in the fixture's folder; the files the example wrote are removed after it."""
    keep = {p.name for p in Path(files).iterdir()}
    try:
        with contextlib.chdir(files):
            return problem(argv)
    finally:
        for path in Path(files).iterdir():
            if path.name not in keep:
                shutil.rmtree(path) if path.is_dir() else path.unlink()


@st.composite
def command_lines(draw):
    return draw(st.sampled_from([scene_parameter_commands, option_commands]))(draw)


FAST = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture],
                derandomize=True)


@FAST
@given(argv=command_lines())
def test_odd_values_give_a_result_or_one_line(files, argv):
    assert fuzz(files, argv) is None


@pytest.mark.slow
@settings(max_examples=1500, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(argv=command_lines())
def test_odd_values_long(files, argv):
    assert fuzz(files, argv) is None


def test_every_scene_parameter_and_option_is_fuzzed():
    """The strategies cover every scene's parameters and every numeric or path option."""
    options = {option for _, option in OPTIONS}
    assert {"--pressure", "--save-at", "--max-steps", "--until", "--out", "--points", "--plot", "--start-index",
            "--vary", "--peak", "--tol", "--t-end", "--frames", "--fps", "--grid", "--workers",
            "--timeout"} <= options
    assert all(SCENES[s].parameters for s in SCENES)
