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

Measured on the 2-core machine (whole process, ``snapmem scenes``): importing numba costs 0.25 s,
pandas 0.2 s, scipy.optimize with scipy.linalg 0.35 s.
"""

from __future__ import annotations

import importlib
import sys
import types

__all__ = ["Kernel", "function", "module", "njit", "materialized"]


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


class Kernel:
    """A function compiled by numba at its first call (see :func:`njit`).

    Attributes
    ----------
    py_func : callable
        The Python function (numpy on arrays where the kernel is elementwise).
    options : dict
        The ``numba.njit`` options (``cache``, ``nogil``, ``inline``, ...).
    """

    def __init__(self, py_func, options: dict):
        self.py_func = py_func
        self.options = options
        self._dispatcher = None
        self.__name__ = py_func.__name__
        self.__qualname__ = py_func.__qualname__
        self.__module__ = py_func.__module__
        self.__doc__ = py_func.__doc__
        self.__wrapped__ = py_func

    @property
    def dispatcher(self):
        """The numba dispatcher (made on first access; compiling happens at its first call)."""
        if self._dispatcher is None:
            import numba
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

    @property
    def signatures(self) -> list:
        """The argument types compiled (or loaded from the cache) so far; [] before the first call."""
        return [] if self._dispatcher is None else list(self._dispatcher.signatures)

    def __call__(self, *args):
        dispatcher = self._dispatcher
        return (dispatcher if dispatcher is not None else self.dispatcher)(*args)

    def __repr__(self) -> str:
        state = "dispatcher made" if self._dispatcher is not None else "not compiled yet"
        return f"<compiled kernel {self.__module__}.{self.__qualname__} ({state})>"


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
    """
    if function is not None:
        return Kernel(function, options)
    return lambda f: Kernel(f, options)


def materialized() -> list[Kernel]:
    """The kernels whose dispatchers this process has made, in order."""
    return list(_made)
