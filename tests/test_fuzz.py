"""Fuzz the command line with odd values: every scene parameter (``--set NAME=VALUE``) and every
numeric or path option of every command gets 0, -1, +-inf, nan, 1e308, 1e-308, '1_0',
full-width digits '１２', an empty string and the like.

The contract checked: no traceback ever; the exit code is 0 (done), 1 (a solver or target
failure, reported as a result) or 2 (bad input); exit 2 prints exactly one line on stderr,
``snapmem: error: ...``; exits 0 and 1 print nothing on stderr (no warnings either).

The CLI runs in-process (:func:`snapmem.cli.main` with captured output), on small scenes and short
runs so that an accepted odd value stays cheap.
"""

import contextlib
import io
import warnings

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from snapmem.catalog.scenes import SCENES
from snapmem.cli import main

ODD = ["0", "-1", "inf", "-inf", "nan", "1e308", "-1e308", "1e-308", "1_0", "１２", "", " ", "0x10", "1e", "--",
       "2.5", "3"]

#: Membrane scenes solved by ``equilibrium`` and ``trace``; every scene by ``simulate``.
STATIC = ("plate", "balloon", "torus")
SMALL = {"nodes": "11"}
#: Short runs: each scene's simulate at few nodes for 2 ms.
SHORT = ["--t-end", "0.002", "--quiet"]


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
    if code not in (0, 1, 2):
        return f"{argv}: exit {code}: {err}"
    lines = err.strip().splitlines()
    if code == 2 and not (len(lines) == 1 and lines[0].startswith("snapmem: error: ")):
        return f"{argv}: exit 2 without exactly one error line: {err!r}"
    if code != 2 and lines:
        return f"{argv}: exit {code} with stderr: {err!r}"
    return None


def sets(params: dict) -> list:
    return [arg for name, value in params.items() for arg in ("--set", f"{name}={value}")]


def scene_parameter_commands(draw):
    scene = draw(st.sampled_from(sorted(SCENES)))
    name = draw(st.sampled_from([p.name for p in SCENES[scene].parameters]))
    value = draw(st.sampled_from(ODD if name != "t_end" else [v for v in ODD if v not in ("2.5", "3")]))
    params = {**({} if name == "nodes" else SMALL), name: value}
    if scene in STATIC:
        return ["equilibrium", scene] + sets(params)
    return ["simulate", scene] + sets({k: v for k, v in params.items() if k != "t_end"}) + (
        SHORT if name != "t_end" else ["--quiet"])


#: (command line before the option, option) for every numeric or path option.
OPTIONS = [
    (["equilibrium", "balloon", "--set", "nodes=11"], "--pressure"),
    (["trace", "balloon", "--set", "nodes=11", "--max-steps", "20"], "--save-at"),
    (["trace", "balloon", "--set", "nodes=11"], "--max-steps"),
    (["trace", "balloon", "--set", "nodes=11", "--max-steps", "20"], "--until"),
    (["trace", "balloon", "--set", "nodes=11", "--max-steps", "20"], "--out"),
    (["trace", "balloon", "--set", "nodes=11", "--max-steps", "20"], "--points"),
    (["trace", "balloon", "--set", "nodes=11", "--max-steps", "20"], "--plot"),
    (["trace", "balloon", "--set", "nodes=11", "--max-steps", "20", "--restart", "branch.npz"], "--start-index"),
    (["fold", "plate", "--set", "nodes=11"], "--vary"),
    (["hysteresis", "balloon", "--set", "nodes=11"], "--peak"),
    (["simulate", "balloon", "--set", "nodes=11", "--t-end", "0.002", "--quiet"], "--tol"),
    (["simulate", "balloon", "--set", "nodes=11", "--quiet"], "--t-end"),
    (["simulate", "balloon", "--set", "nodes=11", "--t-end", "0.002", "--quiet"], "--frames"),
    (["simulate", "balloon", "--set", "nodes=11", "--t-end", "0.002", "--quiet"], "--out"),
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
    value = draw(st.sampled_from(ODD + ["nodir/x.csv", ".", "x.csv", "x.png", "x.gif"]))
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
    with contextlib.chdir(files):
        return problem(argv)


@st.composite
def command_lines(draw):
    return draw(st.sampled_from([scene_parameter_commands, option_commands]))(draw)


FAST = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture],
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
