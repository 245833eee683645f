"""Parameter sweeps that lose no work: one CSV row per design, written the moment it finishes.

``sweep(function, grid, out)`` calls ``function(design)`` for every design (a dict of
parameters) and appends one row per design to the CSV file ``out``, flushed and fsynced at once.
Run it again with the same grid and it skips the designs already in the file, so a sweep killed at
any moment (Ctrl-C, ``kill -9``, a lost node) resumes with no row lost or duplicated; a last line
cut short by the kill is dropped and that design runs again. When every design is done the file is
rewritten in design order (atomically), so a finished file does not depend on how the work was
scheduled or interrupted: the local pool, a Dask cluster and any number of resumes give the same
bytes.

Columns: ``design`` (index in the grid), ``key`` (hash of the design's parameters, what resume
matches on), the parameters, ``status``, the function's outputs, ``message``. A design that fails
is a row too: ``invalid`` (bad input, the message names the parameter), ``error`` (any other
exception), ``timeout`` (ran past the per-design limit and was killed) or ``crashed`` (its worker
process died). A function may return its own ``status`` (the equilibrium job returns the Newton
status: ``converged``, ``no_equilibrium``, ...; see :data:`snapmem.solvers.newton.STATUSES`), otherwise a
finished design is ``ok``. Non-finite numbers are written as empty cells, never as numbers.

Jobs for the command line are registered by name in :data:`JOBS` (``snapmem sweep --job NAME``).

Modules: :mod:`snapmem.sweeps.grid` (designs, keys, axis parsing), :mod:`snapmem.sweeps.journal`
(the row file and its metadata), :mod:`snapmem.sweeps.runners` (process pool, isolation, Dask);
this module has :func:`sweep`, its progress line and the named jobs, and re-exports the names
of the others that it always had.
"""

from __future__ import annotations

import json
import logging
import os
from collections import Counter
from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

from snapmem.errors import SnapmemError, check_int, check_real
from snapmem.io.progress import Progress as _Display
from snapmem.io.progress import bar, duration
from snapmem.sweeps.grid import RESERVED, design_key, designs_of, parse_axis, parse_value, product_grid
from snapmem.sweeps.journal import RowFile, read_rows
from snapmem.sweeps.runners import FAILED, ROW_STATUSES, check_scheduler, run_dask, run_pool

__all__ = ["sweep", "Progress", "EquilibriumJob", "equilibrium_job", "JOBS", "register_job", "make_job",
           "product_grid", "designs_of", "design_key", "parse_axis", "parse_value", "read_rows",
           "ROW_STATUSES", "FAILED", "check_scheduler"]

log = logging.getLogger(__name__)


class Progress:
    """The progress line of a sweep: done/total, rate, time left, failures by status.

    Parameters
    ----------
    total : int
        Designs in the grid.
    done : int
        Designs already in the file when the sweep starts (resumed, not run now).
    enabled : bool
        False: nothing is written (``text()`` still works).
    stream : text stream, optional
        Default ``sys.stderr``; a new line every 10 s when it is not a terminal.
    """

    def __init__(self, total: int, done: int, enabled: bool = True, stream=None):
        self.total, self.done, self.start_done = total, done, done
        self.statuses = Counter()
        self.display = _Display(enabled=enabled, stream=stream)

    def update(self, status: str):
        """One more design finished with ``status``."""
        self.done += 1
        self.statuses[status] += 1
        self.display.show(self.text())

    def text(self) -> str:
        elapsed = self.display.elapsed
        ran = self.done - self.start_done
        rate = ran / elapsed if elapsed > 0 else 0.0
        left = (self.total - self.done) / rate if rate > 0 else float("inf")
        filled = bar(self.done / self.total if self.total else 1.0, 24, empty=".")
        failed = ", ".join(f"{n} {s}" for s, n in sorted(self.statuses.items()) if s in FAILED)
        return (f"sweep {self.done}/{self.total} [{filled}] "
                f"{rate:.1f} designs/s, {duration(elapsed)} elapsed, {duration(left)} left"
                + (f", {failed}" if failed else ""))

    def close(self):
        """Draw the final line (also when every design was already done) and end it."""
        self.display.show(self.text(), force=True)
        self.display.close()


def sweep(function: Callable[[dict], Mapping], grid, out, workers: int | None = None,
          scheduler: str | None = None, timeout: float | None = None, progress: bool = True,
          columns: Sequence[str] | None = None, meta: Mapping | None = None):
    """Run ``function`` on every design of ``grid`` and append one row per design to ``out``.

    Parameters
    ----------
    function : callable
        design (dict) -> dict of scalar outputs, optionally with ``status`` and ``message``.
        If it has a ``warmup()`` method, that runs once per process before designs are forked
        off it (e.g. to compile kernels once instead of once per design).
        It runs in other processes: in the local pool it is inherited by fork (any callable);
        on Dask it is sent with cloudpickle.
    grid : mapping or list of dict
        Axes ``{name: values}`` (all combinations, the last axis fastest) or a list of designs.
    out : path
        CSV file. Designs already in it (matched by ``key``) are skipped.
    workers : int, optional
        Processes of the local pool or of a local Dask cluster (default: the number of cores).
    scheduler : {None, 'local', 'tcp://HOST:PORT'}
        None runs a local process pool; otherwise a Dask cluster (``pip install snapmem[dask]``).
    timeout : float, optional
        Per-design time limit [s]; a design past it is killed and recorded as ``timeout``.
    progress : bool
        Show a progress bar (rate and time left) on stderr.
    columns : sequence of str, optional
        Output column names (default ``function.columns`` if it has them, else the outputs of
        the first design that succeeds).
    meta : mapping, optional
        What the rows depend on besides the design (default ``function.meta``, else the
        function's name), kept in ``<out>.sweep.json`` with the whole grid: resuming with different
        ``meta`` (another job, other fixed parameters) or another grid (other values, another
        order, 1 for 1.0) is refused instead of mixing rows of two sweeps; so is a file that is not
        this sweep's journal, which is left byte for byte as it was.

    Returns
    -------
    pandas.DataFrame
        Every row of ``out`` in design order.
    """
    if not callable(function):
        raise SnapmemError(f"function = {function!r}: must be callable")
    designs = designs_of(grid)
    names = list(designs[0])
    keys = [design_key(d) for d in designs]
    seen = {}
    for i, key in enumerate(keys):
        if key in seen:
            raise SnapmemError(f"grid: designs {seen[key]} and {i} are the same ({designs[i]}): "
                               "every design must differ")
        seen[key] = i
    if workers is None:
        workers = os.cpu_count() or 1
    workers = check_int("workers", workers, minimum=1, maximum=4096)
    if timeout is not None:
        timeout = check_real("timeout", timeout, minimum=0.0, min_inclusive=False)
    scheduler = check_scheduler(scheduler)
    if columns is None:
        columns = getattr(function, "columns", None)
    if columns is not None:
        columns = [str(c) for c in columns]
        clash = RESERVED.union(names).intersection(columns)
        if clash:
            raise SnapmemError(f"columns: {sorted(clash)} clash with the design's parameters or the sweep's columns")

    if meta is None:
        meta = getattr(function, "meta", None)
    if meta is None:
        meta = {"function": f"{getattr(function, '__module__', '?')}.{getattr(function, '__qualname__', repr(function))}"}
    meta = json.loads(json.dumps(dict(meta), sort_keys=True, default=str))

    rows = RowFile(out, names, designs, keys, meta)
    try:
        if rows.outputs is None and columns is not None:
            rows.start(columns)
        elif columns is not None and rows.outputs != columns:
            raise SnapmemError(f"out = {rows.path!r}: has outputs {', '.join(rows.outputs)}; this job writes "
                               f"{', '.join(columns)}: resume with the same job or choose a new file")
        todo = [(i, d) for i, (d, k) in enumerate(zip(designs, keys)) if k not in rows.done]
        resumed = len(designs) - len(todo)
        if resumed:
            log.info("%s: %d of %d designs already done, running %d", rows.path, resumed, len(designs), len(todo))
        display = Progress(len(designs), resumed, enabled=progress)
        waiting = []                      # failed rows finished before the header is known
        if todo:
            run = (run_pool(function, todo, workers, timeout) if scheduler is None
                   else run_dask(function, todo, scheduler, workers, timeout))
            for index, result in run:
                if rows.outputs is None:
                    if result["status"] in FAILED and not result["outputs"]:
                        waiting.append((index, result))
                        display.update(result["status"])
                        continue
                    rows.start(list(result["outputs"]))
                    for held in waiting:
                        rows.append(held[0], keys[held[0]], designs[held[0]], held[1])
                    waiting = []
                rows.append(index, keys[index], designs[index], result)
                display.update(result["status"])
            if rows.outputs is None:
                rows.start([])
            for index, result in waiting:
                rows.append(index, keys[index], designs[index], result)
        display.close()
        rows.finish()
    finally:
        rows.close()
    return read_rows(out)


# ------------------------------------------------------------------------------------------
# named jobs for ``snapmem sweep --job NAME``
@dataclass(frozen=True)
class EquilibriumJob:
    """One equilibrium per design, loaded quasi-statically from rest (:func:`snapmem.statics.equilibrium`).

    A design's parameters override ``fixed`` (both are scene parameters, ``pressure``
    included). Outputs: the scene's measures (volume, u_max, stretch_max, min_tension and its
    probes) and the solver's report (converged, iterations, residual_norm, reason); the row's
    status is the solver's (:data:`snapmem.solvers.newton.STATUSES`).
    """

    scene: str
    fixed: dict = field(default_factory=dict)

    @property
    def meta(self) -> dict:
        """What the rows depend on besides the design (kept beside the CSV, checked on resume)."""
        return {"job": "equilibrium", "scene": self.scene, "fixed": {k: str(v) for k, v in sorted(self.fixed.items())}}

    REPORT = ("converged", "iterations", "residual_norm", "reason")

    @property
    def columns(self) -> list[str]:
        from snapmem.catalog.scenes import build_scene
        scene = build_scene(self.scene)             # the defaults: only the names matter here
        names = scene.measures(scene.reference_state())
        return [name for name in names if name != "taut"] + list(self.REPORT)

    def warmup(self):
        """Solve one small equilibrium so that kernels are compiled before worker processes fork."""
        from snapmem.statics import equilibrium
        from snapmem.catalog.scenes import build_scene
        equilibrium(build_scene(self.scene, nodes=7, pressure=1e-4))

    def __call__(self, design: dict) -> dict:
        from snapmem.statics import equilibrium
        from snapmem.catalog.scenes import build_scene
        eq = equilibrium(build_scene(self.scene, **{**self.fixed, **design}))
        out = {name: value for name, value in eq.measures().items() if name != "taut"}
        report = eq.report
        out.update(converged=report.converged, iterations=report.iterations,
                   residual_norm=report.residual_norm, reason=report.reason, status=report.status)
        return out


def equilibrium_job(scene: str, fixed: Mapping | None = None, axes: Mapping[str, list] | None = None) -> EquilibriumJob:
    """An :class:`EquilibriumJob`; its scene, fixed parameters and every axis value are checked now
    (one clear message each), before any design runs."""
    from snapmem.catalog.scenes import get_spec
    spec = get_spec(scene)
    fixed = dict(fixed or {})
    spec.resolve(**fixed)
    known = {p.name: p for p in spec.parameters}
    for name, values in (axes or {}).items():
        if name not in known:
            raise SnapmemError(f"--grid {name!r}: scene {scene!r} has no such parameter; it has {', '.join(known)}")
        if name in fixed:
            raise SnapmemError(f"{name!r}: given both as a grid axis and a fixed value (--set/--pressure)")
        for value in values:
            known[name].check(value)
    return EquilibriumJob(scene, fixed)


#: name -> factory(scene, fixed parameters, axes {name: values}) -> job callable with ``columns``.
JOBS: dict[str, Callable[..., Callable]] = {"equilibrium": equilibrium_job}


def register_job(name: str, factory: Callable[..., Callable]):
    """Make ``snapmem sweep --job NAME`` run the jobs that ``factory(scene, fixed, axes)`` builds
    (``axes`` maps each grid axis to its values; check them there)."""
    JOBS[name] = factory
    return factory


def make_job(name: str, scene: str, fixed: Mapping | None = None, axes: Mapping[str, list] | None = None):
    """The registered job ``name`` for ``scene`` with ``fixed`` parameters."""
    if name not in JOBS:
        raise SnapmemError(f"job {name!r}: unknown; available: {', '.join(JOBS)}")
    return JOBS[name](scene, fixed, axes)

