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

It also loads snapmem's cached kernels without numba's context refresh
(:func:`_load_without_refresh`): the refresh imports and installs numba's typing and lowering
registries, which only compiling needs (each compile refreshes itself), and it was a third of the
first kernel call of a warm ``snapmem trace``.
"""

from __future__ import annotations

import hashlib
import os
import sys

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


def _load_without_refresh(cache_class, locators: tuple) -> None:
    """Make ``cache_class.load_overload`` skip ``target_context.refresh()`` for kernels whose locator
    is one of ``locators`` (snapmem's), initialising only numba's runtime (NRT), whose functions the
    cached machine code calls.

    What the refresh does: it imports numba's implementation modules and installs their typing and
    lowering registries into the contexts. A cached kernel is machine code plus pickled
    descriptors; rebuilding it (``CompileResult._rebuild``) unserialises the library and takes its
    entry point, and calling it from Python types the arguments by ``typeof``, which is loaded with
    numba. A kernel that compiles later in the process refreshes the contexts first
    (``CompilerBase.__init__``), so it sees every registry. Measured on the warm 101-node trace:
    the first kernel call 0.25 s to 0.11 s in-process, about 0.1 s of CPU per process.
    """
    from numba.core.runtime import nrt
    original = cache_class.load_overload

    def load_overload(self, sig, target_context):
        if not isinstance(getattr(self._impl, "locator", None), locators):
            return original(self, sig, target_context)
        nrt.rtsys.initialize(target_context)
        with self._guard_against_spurious_io_errors():
            return self._load_overload(sig, target_context)

    load_overload.__doc__ = original.__doc__
    cache_class.load_overload = load_overload


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
        stamped = [_stamped(base) for base in bases]
        cache_class = caching.Cache
        if not all(hasattr(cache_class, name) for name in ("load_overload", "_load_overload",
                                                             "_guard_against_spurious_io_errors")):
            raise AttributeError("numba's Cache has moved")
        impl._locator_classes[:0] = stamped
        if os.environ.get("SNAPMEM_CACHE_REFRESH", "0") != "1":
            _load_without_refresh(cache_class, tuple(stamped))
        _installed.append(True)
    except (ImportError, AttributeError, TypeError):
        _installed.append(False)
    return _installed[0]


def cache_dirs(source: str) -> list[str]:
    """Where numba looks for a function's cache (numba.core.caching's locators, in order)."""
    directory = os.path.dirname(os.path.abspath(source))
    subpath = "_".join([os.path.basename(directory), hashlib.sha1(directory.encode()).hexdigest()])
    if os.environ.get("NUMBA_CACHE_DIR"):
        return [os.path.join(os.environ["NUMBA_CACHE_DIR"], subpath)]
    user = os.path.join(os.environ.get("XDG_CACHE_HOME", os.path.expanduser("~/.cache")), "numba", subpath)
    return [os.path.join(directory, "__pycache__"), user]


def in_cache(py_func, qualname: str) -> bool:
    """Whether numba's cache holds an index for kernel ``py_func`` (named ``qualname``) that numba
    will accept: for snapmem's kernels, one carrying the current :func:`kernel_sources_stamp` (read
    from the index's first bytes, without importing numba), else one newer than the source file
    (numba's own stamp). A cheap test made at a kernel's first call (snapmem._lazy's first-use
    policy). A wrong guess costs a compile or a Python run, never a wrong number.

    The stamp, not the file times: a file whose content returns to what the cache holds (a
    revert, a branch switch) is newer than its index, which numba then loads without rewriting;
    a test of times said "not cached" and ran such kernels as Python in every process.
    """
    code = py_func.__code__
    source = code.co_filename
    base = "%s.%s-%d.py%d%d%s.nbi" % (os.path.splitext(os.path.basename(source))[0],
                                      qualname.replace("<", "").replace(">", ""), code.co_firstlineno,
                                      sys.version_info[0], sys.version_info[1], getattr(sys, "abiflags", ""))
    ours = _in_package(source)
    try:
        stamp = kernel_sources_stamp().encode() if ours else os.stat(source).st_mtime
    except OSError:
        return True
    for directory in cache_dirs(source):
        index = os.path.join(directory, base)
        try:
            if ours:
                with open(index, "rb") as file:
                    if stamp in file.read(512):          # numba's version, then (stamp, overloads) pickled
                        return True
            elif os.stat(index).st_mtime >= stamp:
                return True
        except OSError:
            continue
    return False
