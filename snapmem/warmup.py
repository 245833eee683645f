"""Compile ahead: run small versions of the commands so that their kernels are in numba's cache.

numba compiles a kernel at its first call and keeps the machine code on disk (``__pycache__``
beside the module, or ``NUMBA_CACHE_DIR``). After a fresh install the first ``snapmem trace`` or
``snapmem simulate`` therefore pays the compilation; :func:`warmup` pays it once, up front, and
says what it compiled and how long each kernel took::

    snapmem warmup          # continuation (trace) and the compiled time step (simulate)
    snapmem warmup --all    # also every robot experiment's first steps (contacts, bodies)

A kernel already in the cache is loaded, not compiled, and shows a load time of milliseconds.

The compiled time step is compiled for the kinds of terms a scene has (a law other than the
linear-in-invariants ones, linear contacts, balls; see :mod:`snapmem.dynamics.compiled_assembly`):
``snapmem warmup`` compiles the one of torus_snap (no contact), ``--all`` those of every robot
and of a viscoelastic torus_snap (the viscous networks, snapmem.kernels.viscous).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

__all__ = ["Compiled", "Stage", "warmup"]


@dataclass(frozen=True)
class Compiled:
    """One kernel compiled (or loaded from the cache) for one set of argument types.

    Attributes
    ----------
    kernel : str
        Qualified name (module.function).
    seconds : float
        Wall time of its compilation [s], kernels it calls included.
    """

    kernel: str
    seconds: float


@dataclass(frozen=True)
class Stage:
    """One warm-up task: what it ran, its wall time [s] and the kernels it compiled."""

    name: str
    seconds: float
    kernels: tuple[Compiled, ...]


def _trace_balloon():
    from snapmem.catalog.scenes import build_scene
    from snapmem.continuation import trace
    trace(build_scene("balloon", nodes=21), "pressure", until={"stretch_max": 2.5})


def _simulate(name: str, t_end: float | None = None, **params):
    def run():
        from snapmem.catalog.robots import experiment
        from snapmem.dynamics.driver import simulate
        ex = experiment(name, **params)
        simulate(ex.scene, ex.loads, ex.t_end if t_end is None else t_end, rho=ex.rho, damping=ex.damping,
                 q0=ex.q0, v0=ex.v0, options=ex.options, damp_bodies=ex.damp_bodies)
    return run


def _tasks(everything: bool) -> list:
    tasks = [("trace balloon (continuation, limit points)", _trace_balloon),
             ("simulate torus_snap (compiled time step)", _simulate("torus_snap", 2.0))]
    if everything:
        from snapmem.catalog.robots import EXPERIMENTS
        tasks += [(f"simulate {name} (first steps)", _simulate(name, 0.05)) for name in EXPERIMENTS
                  if name != "torus_snap"]
        tasks.append(("simulate torus_snap viscoelastic (compiled viscous networks)",
                      _simulate("torus_snap", 2.0, viscous_mu=1000.0, relaxation_time=10.0)))
    return tasks


def warmup(everything: bool = False, report=None) -> list[Stage]:
    """Compile the kernels the common commands need (``everything``: those of every experiment too).

    Parameters
    ----------
    everything : bool
        Also run the first steps of every robot experiment (``snapmem warmup --all``).
    report : callable, optional
        Called with each :class:`Stage` as it finishes (the CLI prints it).

    Returns
    -------
    list of Stage
    """
    from numba.core import event
    from snapmem._lazy import compiling
    stages = []
    for name, task in _tasks(everything):
        with compiling(), event.install_recorder("numba:compile") as recorder:
            start = time.perf_counter()
            task()
            seconds = time.perf_counter() - start
        stage = Stage(name, seconds, tuple(_compiled(recorder.buffer)))
        stages.append(stage)
        if report is not None:
            report(stage)
    return stages


def _compiled(buffer) -> list[Compiled]:
    """Top-level compilations from a numba event buffer of (timestamp, Event) pairs, in order."""
    open_, found, depth = {}, [], 0
    for stamp, ev in buffer:
        key = id(ev.data["dispatcher"]), str(ev.data["args"])
        if ev.is_start:
            depth += 1
            open_[key] = (stamp, depth)
        else:
            began, level = open_.pop(key, (stamp, depth))
            depth -= 1
            if level == 1:
                function = ev.data["dispatcher"].py_func
                found.append(Compiled(f"{function.__module__}.{function.__qualname__}", stamp - began))
    return found
