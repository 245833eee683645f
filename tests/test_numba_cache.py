"""snapmem's cached kernels are stamped by the source of every module that defines kernels, so a
kernel whose callee (in another file) changed is compiled again, not loaded stale (numba's own
stamp is the kernel's file alone)."""

import os
import sys

from snapmem import _lazy, _numba_cache


def test_the_stamp_follows_every_kernel_module_and_only_those(tmp_path, monkeypatch):
    (tmp_path / "kernels").mkdir()
    caller = tmp_path / "kernels" / "step.py"
    callee = tmp_path / "kernels" / "floor.py"
    plain = tmp_path / "cli.py"
    caller.write_text("from x import njit\n@njit(cache=True)\ndef step(a):\n    return floor(a)\n")
    callee.write_text("@njit(cache=True)\ndef floor(a):\n    return 64 * a\n")
    plain.write_text("print('no kernels here')\n")
    monkeypatch.setattr(_numba_cache, "ROOT", str(tmp_path))

    def stamp():
        monkeypatch.setattr(_numba_cache, "_stamp", [])
        return _numba_cache.kernel_sources_stamp()

    first = stamp()
    assert stamp() == first                                       # deterministic
    plain.write_text("print('still no kernels')\n")
    assert stamp() == first                                       # a module without kernels: no recompile
    callee.write_text("@njit(cache=True)\ndef floor(a):\n    return 65 * a\n")
    assert stamp() != first                                       # the callee changed: every entry is stale


def test_snapmem_kernels_use_the_stamped_locator_and_others_numbas_own():
    numba = _lazy._import_numba()
    from snapmem.kernels.assembly import residual_floor
    ours = numba.njit(cache=True)(residual_floor.py_func)
    locator = ours._cache._impl.locator
    assert type(locator).__name__.startswith("SnapmemStamped")
    assert locator.get_source_stamp() == ("snapmem kernels", _numba_cache.kernel_sources_stamp())

    namespace = {}
    exec(compile("def twice(a):\n    return 2 * a\n", os.path.abspath(__file__), "exec"), namespace)
    theirs = numba.njit(cache=True)(namespace["twice"])
    assert not type(theirs._cache._impl.locator).__name__.startswith("SnapmemStamped")


LOAD_THEN_COMPILE = """
import sys, numpy as np
from snapmem.kernels.linalg import band_ldlt, band_matvec
F, negative, zero, growth = band_ldlt(np.array([[4.0, 4.0, 4.0], [1.0, 1.0, 0.0]]), 1)
loaded_without_registries = "numba.np.arraymath" not in sys.modules
import numba
@numba.njit
def outside(x):                     # not snapmem's: compiled here, after the cached loads
    return np.sum(x * 2.0)
print("@", loaded_without_registries, negative, repr(float(F[2, 0])), outside(np.arange(3.0)),
      float(band_matvec(np.array([[2.0, 2.0], [1.0, 0.0]]), np.ones((2, 1))).sum()))
"""


def test_cached_kernels_load_without_the_registries_and_later_compiles_still_work(tmp_path):
    """The loads skip numba's context refresh; a compile after them (here numba's np.sum, which
    needs numba.np.arraymath's registry) refreshes itself. Run twice on one cache: the first
    process compiles and caches, the second loads."""
    import subprocess
    import sys
    from pathlib import Path
    env = {k: v for k, v in os.environ.items() if k != "SNAPMEM_COLD"}
    env.update(NUMBA_CACHE_DIR=str(tmp_path), SNAPMEM_COLD="compile", SNAPMEM_BACKGROUND_COMPILE="0",
               PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    runs = [subprocess.run([sys.executable, "-c", LOAD_THEN_COMPILE], capture_output=True, text=True, env=env)
            for _ in range(2)]
    for run in runs:
        assert run.returncode == 0, run.stderr[-2000:]
    first, second = (run.stdout.rsplit("@", 1)[1].split() for run in runs)
    assert first[0] == "False" and second[0] == "True"          # compiled (registries) / loaded (none)
    assert first[1:] == second[1:]                                  # the loaded kernel's numbers are the compiled
    assert first[1] == "0" and abs(float(first[2]) - 56.0 / 15.0) < 1e-14   # d_2 = 4 - 1/3.75 = 56/15
    assert first[3:] == ["6.0", "6.0"]


def test_in_cache_reads_the_index_stamp_not_the_file_times(tmp_path, monkeypatch):
    """An index with the current stamp counts even when the source is newer than it (a file whose
    content came back: numba loads that entry and does not rewrite the index); a stale stamp does
    not, whatever the times."""
    import pickle
    import time
    source = tmp_path / "kernels.py"
    source.write_text("def halve(x):\n    return 0.5 * x\n")
    namespace = {}
    exec(compile(source.read_text(), str(source), "exec"), namespace)
    halve = namespace["halve"]
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(_numba_cache, "_in_package", lambda path: True)
    monkeypatch.setattr(_numba_cache, "_stamp", ["0123abcd" * 8])
    directory = _numba_cache.cache_dirs(str(source))[0]
    os.makedirs(directory)
    index = os.path.join(directory, "kernels.halve-1.py%d%d%s.nbi" % (*sys.version_info[:2], getattr(sys, "abiflags", "")))

    def write_index(stamp):
        with open(index, "wb") as file:
            pickle.dump("0.68.1", file, protocol=-1)
            file.write(pickle.dumps((("snapmem kernels", stamp), {}), protocol=-1))

    assert not _numba_cache.in_cache(halve, "halve")                      # no index
    write_index("0123abcd" * 8)
    time.sleep(0.01)
    source.write_text(source.read_text())                                 # newer than the index, same content
    assert os.stat(source).st_mtime > os.stat(index).st_mtime
    assert _numba_cache.in_cache(halve, "halve")
    write_index("ffff0000" * 8)                                           # another tree's kernels
    assert not _numba_cache.in_cache(halve, "halve")
