"""Loading on first use: modules, functions and compiled kernels.

``import snapmem`` and ``snapmem scenes`` need neither numba, nor pandas, nor scipy's big
subpackages; a command loads what it calls, once. Three helpers keep this to the import lines:

- :func:`module` stands for a module (``pd = module("pandas")``) and imports it at the first
  attribute access;
- :func:`function` stands for a function (``brentq = function("scipy.optimize", "brentq")``) and
  imports it at the first call;
- :func:`njit` replaces ``numba.njit``: the decorated function becomes a :class:`Kernel`, which
  imports numba and makes the dispatcher (same options, same on-disk cache) at its first call.
  A kernel that calls other kernels sees them as numba dispatchers: making a dispatcher rebinds
  the kernels its code names, in its module (or its closure), to theirs (numba types globals at compile time).

First use after an install (numba's cache empty): a cached kernel (``cache=True``) that is not in
the cache yet runs as Python, its ``py_func``, instead of compiling for seconds. The operations and
their order are the same, so the numbers are: numba compiles without fastmath and so neither
reorders nor fuses floating-point operations (tests/test_startup_cold.py compares every number
of three traces). This lasts while the process's time in such kernels stays under
:data:`INTERPRET_BUDGET`; past it, the kernels compile. At exit, a detached process compiles the
kernels that ran as Python, for the argument types they saw, so that the next command loads them
(:func:`compile_in_background`). The kernels of the compiled time step (``snapmem.dynamics``:
long loops over steps) always compile, but for those declared ``interpret_uncached`` (:func:`njit`).
``SNAPMEM_COLD=compile`` restores compiling at the first call; ``SNAPMEM_BACKGROUND_COMPILE=0``
turns off the background compile. See docs/performance.md ("First use") for what each costs.
"""

from __future__ import annotations

import atexit
import importlib
import os
import sys
import threading
import time
import types

__all__ = ["Kernel", "function", "module", "njit", "inlined", "materialized", "interpreted", "compiling",
           "python_of", "INTERPRET_BUDGET"]

#: Seconds of Python-run kernels (outermost calls) a process may spend before its uncached kernels
#: compile instead: about what compiling a command's kernels costs, so that a small problem (a
#: 101-node trace) never compiles and a big one takes at most about twice as long as compiling at
#: once would have (figures: docs/performance.md, "First use").
INTERPRET_BUDGET = float(os.environ.get("SNAPMEM_INTERPRET_BUDGET", "10.0"))
#: Modules whose kernels always compile (their loops run for thousands of steps), but for those
#: declared ``interpret_uncached`` (:func:`njit`).
ALWAYS_COMPILED = ("snapmem.dynamics.",)


class _Module:
    """A module imported at the first attribute access (not put in ``sys.modules`` before)."""

    __slots__ = ("_name", "_module")

    def __init__(self, name: str):
        self._name = name
        self._module = None

    def _load(self) -> types.ModuleType:
        if self._module is None:
            self._module = importlib.import_module(self._name)
        return self._module

    def __getattr__(self, attribute: str):
        return getattr(self._load(), attribute)

    def __repr__(self) -> str:
        state = "loaded" if self._module is not None else "not loaded yet"
        return f"<module {self._name!r} ({state})>"


def module(name: str):
    """Stand-in for ``import name``: the module is imported when an attribute is first read."""
    return _Module(name)


def function(module_name: str, name: str):
    """Stand-in for ``from module_name import name`` for a function: imported at its first call."""
    target = None

    def call(*args, **kwargs):
        nonlocal target
        if target is None:
            target = getattr(importlib.import_module(module_name), name)
        return target(*args, **kwargs)

    call.__name__ = call.__qualname__ = name
    call.__doc__ = f"{module_name}.{name}, imported at its first call."
    return call


_made: list["Kernel"] = []        # kernels whose dispatcher exists, in the order they were made


#: numba options every kernel takes unless it sets its own. error_model='numpy': a float division by
#: zero gives inf or nan (as on numpy's arrays, so in the Python twins) instead of raising: numba's
#: default tests every divisor and keeps a branch to raise in each loop (the viscous ball scenes'
#: step ran ~10% slower, docs/performance.md). Any other division is the same IEEE operation.
DEFAULT_OPTIONS = {"error_model": "numpy"}


class Kernel:
    """A function compiled by numba at its first call (see :func:`njit`), or, while numba's cache
    does not hold it, run as Python (the module's docstring says when).

    Attributes
    ----------
    py_func : callable
        The Python function (numpy on arrays where the kernel is elementwise).
    options : dict
        The ``numba.njit`` options (``cache``, ``nogil``, ``inline``, ...), over :data:`DEFAULT_OPTIONS`.
    """

    def __init__(self, py_func, options: dict):
        self.py_func = py_func
        options = dict(options)
        self.interpret_uncached = bool(options.pop("interpret_uncached", False))
        self.options = {**DEFAULT_OPTIONS, **options}
        self._dispatcher = None
        self._twin = None                   # what runs as Python instead of py_func (:meth:`python_twin`)
        self._interpreted = False           # runs as Python in this process (not in the cache yet)
        self._decided = False
        self.__name__ = py_func.__name__
        self.__qualname__ = py_func.__qualname__
        self.__module__ = py_func.__module__
        self.__doc__ = py_func.__doc__
        self.__wrapped__ = py_func

    @property
    def dispatcher(self):
        """The numba dispatcher (made on first access; compiling happens at its first call)."""
        if self._dispatcher is None:
            numba = _import_numba()
            self._dispatcher = numba.njit(**self.options)(self.py_func)
            _made.append(self)
            namespace = self.py_func.__globals__
            if namespace.get(self.__name__) is self:
                namespace[self.__name__] = self._dispatcher
            for name in _global_names(self.py_func.__code__):
                value = namespace.get(name)
                if isinstance(value, Kernel):
                    namespace[name] = value.dispatcher
            for cell in self.py_func.__closure__ or ():          # kernels defined in a function
                if isinstance(cell.cell_contents, Kernel):
                    cell.cell_contents = cell.cell_contents.dispatcher
            _rebind(self, self._dispatcher)
        return self._dispatcher

    def python_twin(self, function):
        """Decorator: ``function`` runs instead of ``py_func`` while the kernel runs as Python. For loop
        kernels slow as Python: the same floating-point operations in the same order, on Python floats or
        whole columns (formulas by :func:`python_of`), the kernel's numbers bit for bit (tests/test_python_twins.py)."""
        self._twin = function
        return function

    @property
    def python(self):
        """What runs while the kernel runs as Python: its twin if it has one, else ``py_func``."""
        return self._twin or self.py_func

    @property
    def signatures(self) -> list:
        """The argument types compiled (or loaded from the cache) so far; [] before the first call."""
        return [] if self._dispatcher is None else list(self._dispatcher.signatures)

    def __call__(self, *args):
        if self.options.get("no_cpython_wrapper"):
            return _run_as_python(self, args)       # no Python entry point (numba's would crash)
        dispatcher = self._dispatcher
        if dispatcher is not None:
            return dispatcher(*args)
        if not self._decided:
            self._decided = True
            self._interpreted = _interpret_when_uncached(self) and not _in_cache(self)
        if self._interpreted and _spent[0] < INTERPRET_BUDGET:
            return _run_as_python(self, args)
        return self.dispatcher(*args)

    def ready(self, args) -> bool:
        """For a kernel whose caller has a Python way of its own (the compiled run's loop, whose
        Python is the driver's): whether to call it now, i.e. its dispatcher is made, numba's
        cache holds it or kernels compile at first call (``SNAPMEM_COLD=compile``). Else False,
        and it compiles for ``args`` in the background at exit, as a kernel run as Python does."""
        if self._dispatcher is not None or _policy["compile"] or not self.options.get("cache") or _in_cache(self):
            return True
        _note_for_background(self, args)
        return False

    def __repr__(self) -> str:
        state = "dispatcher made" if self._dispatcher is not None else "not compiled yet"
        return f"<compiled kernel {self.__module__}.{self.__qualname__} ({state})>"


def _import_numba():
    """``import numba``, with scipy's BLAS table loaded alone beforehand (:mod:`snapmem._scipy_blas`)
    and snapmem's kernels stamped by all their sources (:mod:`snapmem._numba_cache`)."""
    if os.environ.get("SNAPMEM_FULL_SCIPY_LINALG", "0") != "1":
        from snapmem._scipy_blas import load_cython_blas
        load_cython_blas()
    import numba
    from snapmem._numba_cache import install
    install()
    return numba


_spent = [0.0]          # seconds in outermost Python-run kernels, this process
_nesting = threading.local()     # .depth: Python-run kernels open in this thread (only the outermost is timed)
_seen: dict = {}        # (module, qualname) -> set of argument descriptions, of Python-run kernels
_pythons: dict = {}     # py_func -> its copy with the kernels it names bound to their Python (python_of)
_policy = {"compile": os.environ.get("SNAPMEM_COLD", "interpret") == "compile"}


def _interpret_when_uncached(kernel: "Kernel") -> bool:
    return (kernel.options.get("cache", False) and not _policy["compile"]
            and (kernel.interpret_uncached or not kernel.__module__.startswith(ALWAYS_COMPILED)))


def _note_for_background(kernel: "Kernel", args) -> None:
    """Remember ``kernel``'s argument types, to compile it for them at exit (compile_in_background)."""
    key = (kernel.__module__, kernel.__qualname__)
    if key not in _seen:
        _seen[key] = set()
        if len(_seen) == 1 and os.environ.get("SNAPMEM_BACKGROUND_COMPILE", "1") != "0":
            atexit.register(compile_in_background)
    try:
        _seen[key].add(tuple(_describe(a) for a in args))
    except TypeError:
        pass                                  # an argument we cannot describe: not compiled ahead


def _run_as_python(kernel: "Kernel", args):
    depth = getattr(_nesting, "depth", 0)
    if depth:
        return kernel.python(*args)
    _note_for_background(kernel, args)
    import numpy as np
    _nesting.depth = depth + 1
    start = time.perf_counter()
    try:
        with np.errstate(all="ignore"):       # compiled kernels warn of no overflow (inf, NaN) either
            return kernel.python(*args)
    finally:
        _nesting.depth = depth
        _spent[0] += time.perf_counter() - start


class compiling:
    """``with compiling():`` every kernel called inside compiles (or loads) at its first call,
    cached or not (``snapmem warmup`` uses it). Kernels already decided keep their way."""

    def __enter__(self):
        self._before = _policy["compile"]
        _policy["compile"] = True

    def __exit__(self, *exc):
        _policy["compile"] = self._before


def interpreted() -> list[str]:
    """Qualified names of the kernels this process ran as Python (not in numba's cache yet)."""
    return [f"{module}.{name}" for module, name in _seen]


def _in_cache(kernel: "Kernel") -> bool:
    """Whether numba's cache holds the kernel (:func:`snapmem._numba_cache.in_cache`)."""
    from snapmem._numba_cache import in_cache
    return in_cache(kernel.py_func, kernel.__qualname__)


def _describe(value):
    """An argument's numba type, as plain data: ("a", dtype, ndim, layout, writeable) for an array,
    ("t", items[, module, class]) for a (named) tuple, ("s", type name) for a Python or numpy scalar."""
    import numpy as np
    if isinstance(value, np.ndarray):
        layout = "C" if value.flags.c_contiguous else "F" if value.flags.f_contiguous else "A"
        return ("a", value.dtype.str, value.ndim, layout, bool(value.flags.writeable))
    if isinstance(value, tuple) and (type(value) is tuple or hasattr(value, "_fields")):
        named = () if type(value) is tuple else (type(value).__module__, type(value).__qualname__)
        return ("t", tuple(_describe(v) for v in value), *named)
    if isinstance(value, (bool, int, float, complex, np.generic)) or value is None:
        return ("s", type(value).__module__, type(value).__name__)
    raise TypeError(type(value))


def _example(description):
    """A value of the numba type ``description`` names (for ``numba.typeof``)."""
    import numpy as np
    kind = description[0]
    if kind == "a":
        _, dtype, ndim, layout, writeable = description
        shape = (3,) * ndim
        value = np.zeros(shape, dtype=dtype, order="F" if layout == "F" else "C")
        if layout == "A":
            value = np.zeros((6,) + (3,) * (ndim - 1), dtype=dtype)[::2]
        value.flags.writeable = writeable
        return value
    if kind == "t":
        items = tuple(_example(d) for d in description[1])
        return items if len(description) == 2 else getattr(importlib.import_module(description[2]),
                                                            description[3])(*items)
    module, name = description[1], description[2]
    if name == "NoneType":
        return None
    kind_type = getattr(np, name) if module == "numpy" else {"bool": bool, "int": int, "float": float,
                                                              "complex": complex}[name]
    return kind_type(0)


def compile_in_background() -> None:
    """Start a detached process that compiles, into numba's cache, the kernels this process ran as
    Python, for the argument types they were called with (run at exit)."""
    if not _seen:
        return
    import json
    import subprocess
    import tempfile
    lock = _take_compile_lock()
    if lock is None:
        return                        # another process is compiling into this cache (a sweep's workers)
    jobs = [[module, name, [list(map(_plain, d)) for d in descriptions]] for (module, name), descriptions in _seen.items()]
    handle, path = tempfile.mkstemp(prefix="snapmem-compile-", suffix=".json")
    with os.fdopen(handle, "w") as file:
        json.dump(jobs, file)
    environment = dict(os.environ, SNAPMEM_BACKGROUND_COMPILE="0")
    try:
        subprocess.Popen([sys.executable, "-c", "import sys; from snapmem._lazy import compile_jobs; "
                          "compile_jobs(sys.argv[1], sys.argv[2])", path, lock], stdin=subprocess.DEVNULL,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
                         env=environment)
    except OSError:
        os.unlink(path)
        os.unlink(lock)


#: A compile lock older than this [s] is left from a compile that died: taken over.
STALE_LOCK = 900.0


def _take_compile_lock() -> str | None:
    """Create the lock file of background compiles into this cache; None if another holds it."""
    import hashlib
    import tempfile
    place = os.environ.get("NUMBA_CACHE_DIR", "") + os.pathsep + os.path.dirname(os.path.abspath(__file__))
    lock = os.path.join(tempfile.gettempdir(),
                        f"snapmem-compile-{hashlib.sha1(place.encode()).hexdigest()[:16]}.lock")
    for _ in range(2):
        try:
            os.close(os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
            return lock
        except FileExistsError:
            try:
                if time.time() - os.stat(lock).st_mtime < STALE_LOCK:
                    return None
                os.unlink(lock)
            except OSError:
                return None
        except OSError:
            return None
    return None


def _plain(part):
    return [_plain(p) for p in part] if isinstance(part, tuple) else part


def _tupled(part):
    return tuple(_tupled(p) for p in part) if isinstance(part, list) else part


def compile_jobs(path: str, lock: str | None = None) -> list[tuple[str, float]]:
    """Compile the kernels listed in a job file of :func:`compile_in_background` (then delete it,
    and the ``lock`` file when done). Returns (kernel, seconds) for each."""
    try:
        return _compile_jobs(path)
    finally:
        if lock is not None and os.path.exists(lock):
            os.unlink(lock)


def _compile_jobs(path: str) -> list[tuple[str, float]]:
    import json
    import numba
    with open(path) as file:
        jobs = json.load(file)
    os.unlink(path)
    done = []
    for module_name, qualname, descriptions in jobs:
        kernel = importlib.import_module(module_name)
        for part in qualname.split("."):
            kernel = getattr(kernel, part)
        dispatcher = kernel.dispatcher if isinstance(kernel, Kernel) else kernel
        start = time.perf_counter()
        for description in descriptions:
            types_ = tuple(numba.typeof(_example(_tupled(d))) for d in description)
            dispatcher.compile(types_)
        done.append((f"{module_name}.{qualname}", time.perf_counter() - start))
    return done


def _rebind(kernel: "Kernel", dispatcher) -> None:
    """Point every name in a loaded snapmem module that holds ``kernel`` (``from ... import``
    copies) at its dispatcher, so later calls go to numba without this wrapper's Python call
    (docs/performance.md)."""
    for module in list(sys.modules.values()):
        namespace = getattr(module, "__dict__", None)
        if namespace is None or not getattr(module, "__name__", "").startswith("snapmem"):
            continue
        for name, value in list(namespace.items()):
            if value is kernel:
                namespace[name] = dispatcher


def _global_names(code) -> set[str]:
    """Names a code object (and the code nested in it) may read as globals."""
    names = set(code.co_names)
    for constant in code.co_consts:
        if isinstance(constant, types.CodeType):
            names |= _global_names(constant)
    return names


def njit(function=None, **options):
    """Drop-in for ``numba.njit`` that defers importing numba to the kernel's first call.

    Used as ``@njit(cache=True, nogil=True)`` (or bare ``@njit``). Returns a :class:`Kernel`.
    snapmem's own option ``interpret_uncached=True``: a kernel of :data:`ALWAYS_COMPILED` that Python
    calls a few times a command runs as Python while uncached, like any other (give it a fast twin).
    """
    if function is not None:
        return Kernel(function, options)
    return lambda f: Kernel(f, options)


def inlined(function):
    """A compiled-code copy of the plain Python ``function``: numba inlines it into the kernels that
    call it (it is no kernel of its own), while Python keeps calling ``function`` itself, at no
    dispatch cost. For the scalar formulas a compiled loop and its Python twin both take, so
    that each is written once (snapmem.dynamics: the schemes' and the step control's)."""
    return Kernel(function, {"cache": True, "nogil": True, "no_cpython_wrapper": True, "no_cfunc_wrapper": True,
                             "inline": "always"})


def python_of(function):
    """The Python of ``function`` (a Kernel, a dispatcher, a function) with the kernels it names bound
    to their Python (twin or ``py_func``), recursively, and a ``py_func`` (itself): how a twin calls a
    formula on arrays. Those names may be numba dispatchers already (:attr:`Kernel.dispatcher`
    rebinds them), which would compile for arrays. Module names are read once, at first use."""
    function = function.python if isinstance(function, Kernel) else getattr(function, "py_func", function)
    if function not in _pythons:
        namespace = dict(function.__globals__)
        done = _pythons[function] = types.FunctionType(function.__code__, namespace, function.__name__,
                                                       function.__defaults__, function.__closure__)
        done.py_func = done
        for name in _global_names(function.__code__):
            value = namespace.get(name)                           # a Kernel, or the dispatcher it made
            kernel = value if isinstance(value, Kernel) else next((k for k in _made if k._dispatcher is value), None)
            if kernel is not None:
                namespace[name] = python_of(kernel)
    return _pythons[function]


def materialized() -> list[Kernel]:
    """The kernels whose dispatchers this process has made, in order."""
    return list(_made)

