"""Every tutorial of docs/tutorials/ runs on its quick settings and gets the right number: the
limit points against the exact thin-sphere formulas, the sweep's stretches against the exact
stretch, the snap time of torus_snap, the user scene's equilibrium stretch."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest


TUTORIALS = Path(__file__).resolve().parents[1] / "docs" / "tutorials"


def run(name, tmp_path, *extra):
    """Import the tutorial script ``name`` (its folder on sys.path, as when run) and call its main;
    the scenes and laws it registers are unregistered afterwards (other tests loop over all)."""
    from snapmem.catalog.registry import SCENES
    from snapmem.model.materials import LAWS
    scenes, laws = dict(SCENES), dict(LAWS)
    sys.path.insert(0, str(TUTORIALS))
    try:
        spec = importlib.util.spec_from_file_location(f"tutorial_{name}", TUTORIALS / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module.main(["--quick", "--out", str(tmp_path), *extra])
    finally:
        sys.path.remove(str(TUTORIALS))
        SCENES.clear(), SCENES.update(scenes)
        LAWS.clear(), LAWS.update(laws)


def test_every_tutorial_is_tested_and_indexed():
    scripts = sorted(p.stem for p in TUTORIALS.glob("t[0-9]_*.py"))
    assert len(scripts) == 6
    tested = {name for name in globals() if name.startswith("test_t")}
    assert all(any(t.startswith(f"test_{s[:2]}_") for t in tested) for s in scripts)
    index = (TUTORIALS / "README.md").read_text()
    assert all(f"{s}.py" in index for s in scripts)


def test_t1_limit_point_of_the_traced_balloon(tmp_path):
    lp, (lam, p) = run("t1_trace_limit_point", tmp_path)
    assert lp["located"]
    assert lp["control"] == pytest.approx(p, rel=2e-3)          # 41 nodes: 7.7e-4 off the thin sphere
    assert lp["stretch_max"] == pytest.approx(lam, rel=5e-3)
    assert (tmp_path / "balloon_branch.csv").stat().st_size > 0


def test_t2_limit_point_map_falls_with_the_voltage(tmp_path):
    table = run("t2_limit_point_map", tmp_path)
    assert table["exists"].all()
    np.testing.assert_allclose(table["limit"], table["p_limit_exact"], rtol=3e-3)
    assert np.all(np.diff(table["limit"]) < 0)


@pytest.mark.parametrize("scheduler", ["local", "pool"])
def test_t3_sweep_gives_the_exact_stretches(tmp_path, scheduler):
    if scheduler == "local":
        pytest.importorskip("dask.distributed", reason="the Dask scheduler needs snapmem[dask] (dask.distributed)")
    table = run("t3_sweep_dask", tmp_path, "--scheduler", scheduler)
    assert list(table["status"]) == ["converged"] * 6
    np.testing.assert_allclose(table["stretch"], table["stretch_exact"], rtol=2e-3)


def test_t4_snap_time_and_export(tmp_path):
    traj, snap, series = run("t4_snap_replay_vtk", tmp_path)
    assert traj.meta["status"] == "completed"
    assert snap["snap"] == pytest.approx(5.5495, abs=0.05)       # `snapmem simulate torus_snap` (t_end 100 s)
    assert (tmp_path / "torus_snap.npz").exists()
    import meshio
    frames = [Path(f) for f in series.membrane]
    assert len(frames) == len(traj["t"]) and Path(series.pvd).exists()
    mesh = meshio.read(frames[-1])
    assert mesh.points.shape[0] % 16 == 0 and np.isfinite(mesh.points).all()      # the meridian x 16 segments


def test_t5_user_law_limit_point_by_hand(tmp_path):
    lp, (lam, p) = run("t5_own_law", tmp_path)
    assert lp["control"] == pytest.approx(p, rel=3e-3)
    assert lp["stretch_max"] == pytest.approx(lam, rel=5e-3)


def test_t6_user_scene_equilibrium_stretch(tmp_path):
    stretch, lam = run("t6_own_scene", tmp_path)
    assert stretch == pytest.approx(lam, rel=2e-3)                # 41 nodes: 5e-4 off the thin sphere


def test_docs_site_has_every_page_and_the_tutorials(tmp_path):
    """``python docs/build.py`` (here without the pdoc API pages, which take 20 s): one HTML page
    per Markdown page of docs/, the tutorials' index linking to their copied scripts."""
    sys.path.insert(0, str(TUTORIALS.parent))
    try:
        spec = importlib.util.spec_from_file_location("docs_build", TUTORIALS.parent / "build.py")
        build = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(build)
    finally:
        sys.path.remove(str(TUTORIALS.parent))
    pytest.importorskip("markdown2", reason="the docs build needs snapmem[docs] (pdoc, markdown2)")
    index = build.build(tmp_path / "site", api=False)
    pages = build.pages()
    assert index.exists() and len(list((tmp_path / "site").glob("*.html"))) == len(pages)
    tutorials = (tmp_path / "site" / "tutorials_index.html").read_text()
    assert all(f'href="tutorials/t{i}_' in tutorials for i in range(1, 7))
    assert all((tmp_path / "site" / "tutorials" / f"{s.name}").exists() for s in TUTORIALS.glob("t[0-9]_*.py"))
