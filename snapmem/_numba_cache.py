"""numba's on-disk cache, made to notice when a kernel's callees change.

numba keys a cached kernel on its own source file's modification time and size only. A kernel
that calls kernels of other files (the compiled time step calls the assembly, the laws, the
barriers, the band solver) is loaded from the cache unchanged after any of those files changes:
after a ``git pull`` into an editable install, the old machine code would run against the new
Python, silently. That happened while this package was developed (a compiled step kept an old
``residual_floor``).

:func:`install` puts a stamp on snapmem's kernels in place of numba's: a hash of the source of
every snapmem module that defines kernels. A change to any of them invalidates every snapmem
entry, which numba then compiles again (or :mod:`snapmem._lazy` runs as Python meanwhile). The
cache's location and everything else of numba's caching is unchanged, and other packages'
kernels keep numba's own stamp. It uses numba's cache-locator classes
(``numba.core.caching``); should a numba release move them, :func:`install` does nothing and
numba's own behaviour remains.
"""

from __future__ import annotations

import hashlib
import os

ROOT = os.path.dirname(os.path.abspath(__file__))
_stamp: list = []
_installed: list = []


def kernel_sources_stamp() -> str:
    """A hash of the source of every snapmem module that defines kernels (computed once per process:
    about 6 ms, reading the package's files)."""
    if not _stamp:
        digest = hashlib.sha256()
        for folder, dirs, files in sorted(os.walk(ROOT)):
            dirs.sort()
            for name in sorted(files):
                if not name.endswith(".py"):
                    continue
                path = os.path.join(folder, name)
                with open(path, "rb") as handle:
                    source = handle.read()
                if b"njit" in source:
                    digest.update(os.path.relpath(path, ROOT).encode() + b"\0" + source + b"\0")
        _stamp.append(digest.hexdigest())
    return _stamp[0]


def _in_package(py_file: str) -> bool:
    return os.path.abspath(py_file).startswith(ROOT + os.sep)


def _stamped(base):
    """A locator class like numba's ``base`` whose source stamp is :func:`kernel_sources_stamp`,
    for snapmem's files only."""

    class Stamped(base):
        def get_source_stamp(self):
            return ("snapmem kernels", kernel_sources_stamp())

        @classmethod
        def from_function(cls, py_func, py_file):
            if not _in_package(py_file):
                return None
            return super().from_function(py_func, py_file)

    Stamped.__name__ = Stamped.__qualname__ = f"SnapmemStamped{base.__name__}"
    return Stamped


def install() -> bool:
    """Give snapmem's cached kernels the package stamp (once; before any kernel is compiled or
    loaded). True if installed."""
    if _installed:
        return _installed[0]
    try:
        from numba.core import caching
        impl = caching.CacheImpl
        bases = [c for c in impl._locator_classes if hasattr(c, "get_source_stamp")]
        if not bases:
            raise AttributeError("no locator classes")
        impl._locator_classes[:0] = [_stamped(base) for base in bases]
        _installed.append(True)
    except (ImportError, AttributeError, TypeError):
        _installed.append(False)
    return _installed[0]
