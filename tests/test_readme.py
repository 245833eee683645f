"""Every Python block of the README runs, and asserts what it claims; the quick start's commands
are the ones CI runs."""

import re
from pathlib import Path

import pytest

README = (Path(__file__).resolve().parents[1] / "README.md").read_text()
BLOCKS = re.findall(r"```python\n(.*?)```", README, flags=re.S)


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_readme_python_block_runs(index, tmp_path, monkeypatch):
    if '__name__ == "__main__"' in BLOCKS[index]:
        pytest.skip("a block for a process pool runs as a script in tests/test_sweep.py")
    monkeypatch.chdir(tmp_path)
    namespace = {}
    exec(compile(BLOCKS[index], f"README block {index}", "exec"), namespace)   # the block's own asserts run
    assigned = set(re.findall(r"^(\w+)\s*=", BLOCKS[index], flags=re.M))
    assert assigned and assigned <= set(namespace)            # it ran to its end and bound its results


def test_readme_has_blocks_with_assertions():
    assert len(BLOCKS) >= 4 and all("assert" in b for b in BLOCKS)


def test_ci_runs_the_readme_test_command():
    ci = (Path(__file__).resolve().parents[1] / ".ci" / "run").read_text()
    lines = README.splitlines()
    i = lines.index("# install what the tests need and run them")
    assert lines[i + 1] == 'pip install -e ".[test]" && python -m pytest'
    assert "# install what the tests need and run them" in ci


def test_quick_start_main_job_runs(tmp_path, monkeypatch):
    """The first quick-start command's snapmem part, on a smaller mesh."""
    from snapmem.cli import main
    monkeypatch.chdir(tmp_path)
    line = next(l for l in README.splitlines() if "snapmem trace balloon" in l and "pip install" in l)
    argv = line.split("&& snapmem ", 1)[1].split() + ["--set", "nodes=41"]
    assert main(argv) == 0
    import pandas as pd
    points = pd.read_csv("balloon_points.csv")
    assert points["kind"].iloc[0] == "LP" and abs(points["pressure"].iloc[0] / 1.407327e-2 - 1) < 2e-3
    assert Path("balloon.png").stat().st_size > 1000 and len(pd.read_csv("balloon.csv")) > 10
