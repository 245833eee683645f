"""Running the designs of a sweep: each design in a process of its own, so that one that hangs or
crashes costs only that design.

Every runner yields ``(index, result)`` as designs finish, where a result is ``{'status',
'message', 'outputs'}`` with the outputs as CSV cells (:func:`call` never raises: a failed
design is a result too). :func:`run_pool` is a local process pool of our own (a hung design's
worker is killed at its time limit, a dead worker replaced); :func:`run_dask` sends the designs
to a Dask cluster, each run by :func:`call_isolated` in a forked child.
"""

from __future__ import annotations

import logging
import math
import multiprocessing
import multiprocessing.connection
import os
import pickle
import select
import signal
import time
from collections import deque
from dataclasses import dataclass
from numbers import Real
from typing import Callable, Mapping

import numpy as np

from snapmem.errors import SnapmemError
from snapmem.sweeps.journal import cell

log = logging.getLogger(__name__)

#: Row statuses the sweep itself gives (a function's own ``status`` is kept as it is).
ROW_STATUSES = {
    "ok": "the function returned its outputs (and no status of its own)",
    "invalid": "bad input (SnapmemError): the message names the parameter, its value and what is allowed",
    "error": "the function raised another exception: the message gives its type and text",
    "timeout": "the design ran longer than the per-design time limit and its process was killed",
    "crashed": "the process running the design died (out of memory, a segfault, os._exit)",
}
FAILED = ("invalid", "error", "timeout", "crashed")


def call(function: Callable, design: dict) -> dict:
    """Run one design: {'status', 'message', 'outputs'} with outputs as CSV cells; never raises."""
    try:
        result = function(dict(design))
        if result is None:
            result = {}
        if not isinstance(result, Mapping):
            raise TypeError(f"the function returned {type(result).__name__}, not a dict of outputs")
        result = dict(result)
        status = str(result.pop("status", "ok")) or "ok"
        message = result.pop("message", "")
        outputs = {}
        for name, value in result.items():
            if isinstance(value, np.ndarray) and value.ndim == 0:
                value = value.item()
            if value is not None and not isinstance(value, (str, bool, Real, np.bool_, np.integer, np.floating)):
                raise TypeError(f"output {name!r} is a {type(value).__name__}, not a number or string")
            outputs[str(name)] = cell(value)
        return {"status": status, "message": cell(message), "outputs": outputs}
    except SnapmemError as exc:
        return {"status": "invalid", "message": cell(str(exc)), "outputs": {}}
    except Exception as exc:                                       # a failed design is a row
        return {"status": "error", "message": cell(f"{type(exc).__name__}: {exc}"), "outputs": {}}


def _failed(status: str, message: str) -> dict:
    return {"status": status, "message": message, "outputs": {}}


def _die_with_parent():
    """Ask Linux to SIGKILL this process when its parent dies (a killed sweep leaves no workers)."""
    try:
        import ctypes
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)        # PR_SET_PDEATHSIG
    except Exception:                                                     # not Linux: poll below
        pass


def _worker_main(function, conn, inherited, parent_pid):
    """A pool worker: receive (index, design), send back the result of ``call``, until EOF or
    until the parent is gone."""
    _die_with_parent()
    signal.signal(signal.SIGINT, signal.SIG_IGN)          # the parent handles Ctrl-C
    for other in inherited:                               # pipe ends a fork copied from the parent
        other.close()
    while True:
        try:
            while not conn.poll(1.0):
                if os.getppid() != parent_pid:
                    return
            task = conn.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        conn.send(call(function, task[1]))


def _died(exitcode) -> dict:
    return _failed("crashed", f"the process running the design died (exit code {exitcode})")


_WARM = set()


def _warm_up(function):
    """Call ``function.warmup()`` once per process, if it has one: what it loads or compiles
    (numba kernels, imports) is then inherited by every forked child instead of redone per design."""
    key = (type(function).__module__, type(function).__qualname__, repr(getattr(function, "meta", None)))
    if key in _WARM:
        return
    _WARM.add(key)
    warm = getattr(function, "warmup", None)
    if callable(warm):
        try:
            warm()
        except Exception as exc:                     # a warm-up is only an optimisation
            log.debug("warm-up of %r failed: %s", function, exc)


def call_isolated(function, design: dict, timeout: float | None) -> dict:
    """``call`` in a forked child, killed after ``timeout`` seconds (for Dask workers, whose
    tasks run in threads that cannot be stopped, and so that a crash takes down only the child,
    as in the local pool). Inline where there is no fork."""
    if not hasattr(os, "fork"):
        return call(function, design)
    _warm_up(function)
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:                                                   # child
        try:
            os.close(read_fd)
            data = pickle.dumps(call(function, design))
            view = memoryview(data)
            while view:
                view = view[os.write(write_fd, view):]
        finally:
            os._exit(0)
    os.close(write_fd)
    chunks, timed_out = [], False
    deadline = math.inf if timeout is None else time.monotonic() + timeout
    try:
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                timed_out = True
                break
            ready, _, _ = select.select([read_fd], [], [], None if left == math.inf else left)
            if ready:
                chunk = os.read(read_fd, 1 << 16)
                if not chunk:
                    break
                chunks.append(chunk)
    finally:
        os.close(read_fd)
        if timed_out:
            os.kill(pid, signal.SIGKILL)
        exitcode = os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])
    if timed_out:
        return _failed("timeout", f"killed after the time limit of {timeout:g} s")
    try:
        return pickle.loads(b"".join(chunks))
    except Exception:
        return _died(exitcode)


def run_pool(function, tasks, workers: int, timeout: float | None):
    """Our own process pool, so that one hung or crashed design kills only its own worker."""
    method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
    ctx = multiprocessing.get_context(method)

    @dataclass
    class Worker:
        process: object
        conn: object
        task: tuple | None = None
        started: float = 0.0

    pool = []

    def start():
        parent, child = ctx.Pipe()
        inherited = [parent, *(w.conn for w in pool)] if method == "fork" else []
        process = ctx.Process(target=_worker_main, args=(function, child, inherited, os.getpid()), daemon=True)
        process.start()
        child.close()
        return Worker(process, parent)

    def stop(worker, kill=False):
        if kill and worker.process.is_alive():
            worker.process.kill()
        try:
            worker.conn.close()
        except OSError:
            pass
        worker.process.join(5)
        if worker.process.is_alive():
            worker.process.kill()
            worker.process.join()

    pending = deque(tasks)
    if method == "fork":
        _warm_up(function)                                 # once here, inherited by every worker
    for _ in range(min(workers, len(pending)) or 1):
        pool.append(start())
    try:
        while True:
            for i, worker in enumerate(pool):
                if worker.task is None and pending:
                    if not worker.process.is_alive():            # died after its last result
                        stop(worker)
                        pool[i] = worker = start()
                    worker.task = pending.popleft()
                    worker.started = time.monotonic()
                    try:
                        worker.conn.send(worker.task)
                    except OSError:                              # seen as dead just below
                        pass
            busy = [w for w in pool if w.task is not None]
            if not busy:
                break
            wait = 0.5
            if timeout is not None:
                wait = max(0.0, min(wait, min(w.started + timeout for w in busy) - time.monotonic()))
            ready = multiprocessing.connection.wait([w.conn for w in busy] + [w.process.sentinel for w in busy], wait)
            for i, worker in enumerate(pool):
                if worker.task is None:
                    continue
                index = worker.task[0]
                result = None
                if worker.conn in ready or worker.process.sentinel in ready:
                    try:
                        result = worker.conn.recv() if worker.conn.poll() else None
                    except (EOFError, OSError):
                        result = None
                    if result is None:
                        stop(worker, kill=True)
                        result = _died(worker.process.exitcode)
                        pool[i] = worker = start()
                elif timeout is not None and time.monotonic() - worker.started >= timeout:
                    result = _failed("timeout", f"killed after the time limit of {timeout:g} s")
                    stop(worker, kill=True)
                    pool[i] = worker = start()
                if result is not None:
                    worker.task = None
                    yield index, result
    finally:
        for worker in pool:
            try:
                if worker.task is None:
                    worker.conn.send(None)
            except OSError:
                pass
            stop(worker, kill=worker.task is not None)


def _dask_client(scheduler: str, workers: int):
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise SnapmemError(f"scheduler = {scheduler!r}: needs Dask; install it with "
                           "pip install 'snapmem[dask]' (or use the local pool: no --scheduler)") from None
    if scheduler == "local":
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=":0", silence_logs=logging.WARNING)
        return Client(cluster), cluster
    try:
        return Client(scheduler, timeout=30), None
    except (OSError, TimeoutError) as exc:
        raise SnapmemError(f"scheduler = {scheduler!r}: cannot connect ({exc})") from None


def run_dask(function, tasks, scheduler: str, workers: int, timeout: float | None):
    """The same designs as tasks on a Dask distributed cluster; each design still runs in
    ``call`` (in a forked child when there is a time limit)."""
    from dask.distributed import as_completed
    client, cluster = _dask_client(scheduler, workers)
    try:
        futures = {}
        for index, design in tasks:
            future = client.submit(call_isolated, function, design, timeout, pure=False)
            futures[future] = index
        for future in as_completed(list(futures)):
            index = futures.pop(future)
            try:
                result = future.result()
            except Exception as exc:                  # a worker died under the task
                result = _failed("crashed", f"the Dask task failed: {type(exc).__name__}: {exc}")
            future.release()
            yield index, result
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def check_scheduler(scheduler):
    """None (local process pool), 'local' (a local Dask cluster) or 'tcp://HOST:PORT'."""
    if scheduler is None:
        return None
    if not isinstance(scheduler, str):
        raise SnapmemError(f"scheduler = {scheduler!r}: must be 'local' or 'tcp://HOST:PORT'")
    if scheduler == "local":
        return scheduler
    host, sep, port = scheduler.removeprefix("tcp://").rpartition(":")
    if not scheduler.startswith("tcp://") or not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise SnapmemError(f"scheduler = {scheduler!r}: must be 'local' or 'tcp://HOST:PORT'")
    return scheduler
