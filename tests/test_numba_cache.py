"""snapmem's cached kernels are stamped by the source of every module that defines kernels, so a
kernel whose callee (in another file) changed is compiled again, not loaded stale (numba's own
stamp is the kernel's file alone)."""

import os

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
