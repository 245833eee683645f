"""scipy's BLAS function table without the rest of scipy.linalg (start-up, issue 17).

numba's kernels call BLAS through ``scipy.linalg.cython_blas``; importing it the usual way runs
``scipy/linalg/__init__.py``, which imports all of scipy.linalg. snapmem._lazy calls
:func:`load_cython_blas` before it imports numba.
"""

from __future__ import annotations

import sys
import types


def load_cython_blas() -> None:
    """Import ``scipy.linalg.cython_blas`` (the BLAS function table numba's kernels call through)
    without running ``scipy/linalg/__init__.py``, which imports all of scipy.linalg (its cost:
    docs/performance.md, "Start-up").

    numba imports that module at its first compilation (its BLAS probe) and whenever a kernel
    using BLAS is loaded from the cache (the compiled time step's ``residual @ dx``). The table is
    an extension module that needs nothing else from scipy.linalg; a placeholder package stands in
    for scipy.linalg while it loads and is removed at once, and the real scipy.linalg, when imported
    later, is the complete package with this same module as its ``cython_blas``.
    ``SNAPMEM_FULL_SCIPY_LINALG=1`` imports scipy.linalg as usual instead.
    """
    if "scipy.linalg" in sys.modules or "scipy.linalg.cython_blas" in sys.modules:
        return
    try:
        import importlib.util
        import scipy
        spec = importlib.util.find_spec("scipy.linalg")
    except ImportError:
        return
    if spec is None or not spec.submodule_search_locations:
        return
    import _imp
    placeholder = types.ModuleType("scipy.linalg")
    placeholder.__path__ = list(spec.submodule_search_locations)
    _imp.acquire_lock()               # the global import lock (reentrant): no other thread imports meanwhile
    try:
        if "scipy.linalg" in sys.modules:
            return
        sys.modules["scipy.linalg"] = placeholder
        try:
            importlib.import_module("scipy.linalg.cython_blas")
        except ImportError:
            return
        finally:
            if sys.modules.get("scipy.linalg") is placeholder:
                del sys.modules["scipy.linalg"]
            if vars(scipy).get("linalg") is placeholder:       # (getattr would import scipy.linalg)
                del scipy.linalg
        sys.meta_path.insert(0, _AttachCythonBlas())
    finally:
        _imp.release_lock()


class _AttachCythonBlas:
    """Import hook, used once: the real scipy.linalg, when imported, gets the ``cython_blas``
    attribute the import system would have set had it loaded the module itself."""

    def find_spec(self, name, path=None, target=None):
        if name != "scipy.linalg":
            return None
        sys.meta_path.remove(self)
        import importlib.util
        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None:
            return spec
        execute = spec.loader.exec_module

        def exec_module(module):
            execute(module)
            module.cython_blas = sys.modules["scipy.linalg.cython_blas"]

        spec.loader.exec_module = exec_module
        return spec
