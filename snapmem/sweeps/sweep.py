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
"""

from __future__ import annotations

import csv
import hashlib
import io
import itertools
import json
import logging
import math
import multiprocessing
import multiprocessing.connection
import os
import pickle
import select
import signal
import sys
import time
from collections import Counter, deque
from dataclasses import dataclass, field
from numbers import Integral, Real
from typing import Callable, Iterable, Mapping, Sequence

import numpy as np

from snapmem.errors import SnapmemError, check_int, check_real

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
_LEADING = ("design", "key")
_RESERVED = {"design", "key", "status", "message"}


# ------------------------------------------------------------------------------------------
# designs
def product_grid(axes: Mapping[str, Sequence]) -> list[dict]:
    """Every combination of the axes' values, the last axis varying fastest.

    >>> product_grid({"R": [1, 2], "H": [0.1, 0.2]})[1]
    {'R': 1, 'H': 0.2}
    """
    names = list(axes)
    for name in names:
        values = axes[name]
        if isinstance(values, (str, bytes)) or not isinstance(values, Iterable):
            raise SnapmemError(f"grid axis {name!r} = {values!r}: must be a list of values")
    return [dict(zip(names, combo)) for combo in itertools.product(*(list(axes[n]) for n in names))]


def _scalar(name: str, value):
    """A design value as a plain Python bool, int, finite float or one-line str."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (Integral, np.integer)):
        return int(value)
    if isinstance(value, (Real, np.floating)):
        return check_real(name, float(value))
    if isinstance(value, str):
        if "\n" in value or "\r" in value:
            raise SnapmemError(f"{name} = {value!r}: must be one line")
        return value
    raise SnapmemError(f"{name} = {value!r}: must be a number or a string (got {type(value).__name__})")


def designs_of(grid) -> list[dict]:
    """The list of designs of ``grid``: a mapping of axes (their product) or a list of dicts.

    Every design must have the same parameter names; values are plain numbers or strings.
    """
    if isinstance(grid, Mapping):
        designs = product_grid(grid) if grid else []
    elif isinstance(grid, (str, bytes)) or not isinstance(grid, Iterable):
        raise SnapmemError(f"grid = {grid!r}: must be a mapping of axes or a list of designs (dicts)")
    else:
        designs = list(grid)
    if not designs:
        raise SnapmemError("grid: has no designs")
    names = None
    out = []
    for i, design in enumerate(designs):
        if not isinstance(design, Mapping):
            raise SnapmemError(f"grid design {i} = {design!r}: must be a dict of parameters")
        for key in design:
            if not isinstance(key, str) or not key.strip():
                raise SnapmemError(f"grid design {i}: parameter name {key!r} must be a non-empty string")
            if key in _RESERVED:
                raise SnapmemError(f"grid parameter {key!r}: reserved for the sweep's own columns "
                                   f"({', '.join(sorted(_RESERVED))})")
        if names is None:
            names = list(design)
        elif set(design) != set(names):
            raise SnapmemError(f"grid design {i}: parameters {sorted(design)}; design 0 has {sorted(names)}: "
                               "every design needs the same names")
        out.append({name: _scalar(name, design[name]) for name in names})
    return out


def design_key(design: Mapping) -> str:
    """A stable 16-hex-digit key of a design's parameters (order of the names does not matter)."""
    text = json.dumps(design, sort_keys=True, separators=(",", ":"))
    return hashlib.sha1(text.encode()).hexdigest()[:16]


def parse_axis(text: str):
    """``NAME=START:STOP:COUNT`` (evenly spaced) or ``NAME=v1,v2,...`` -> (name, list of values)."""
    name, sep, spec = str(text).partition("=")
    name, spec = name.strip(), spec.strip()
    usage = "must be NAME=START:STOP:COUNT or NAME=v1,v2,..."
    if not sep or not name or not spec:
        raise SnapmemError(f"--grid {text!r}: {usage}")
    if ":" in spec:
        parts = spec.split(":")
        if len(parts) != 3:
            raise SnapmemError(f"--grid {text!r}: {usage}")
        start, stop = (check_real(f"{name} {what}", parse_value(f"{name} {what}", p, number=True))
                       for what, p in zip(("START", "STOP"), parts[:2]))
        count = check_int(f"{name} COUNT", parse_value(f"{name} COUNT", parts[2], number=True), minimum=1,
                          maximum=10_000_000)
        return name, [float(v) for v in np.linspace(start, stop, count)]
    values = [v.strip() for v in spec.split(",")]
    if any(not v for v in values):
        raise SnapmemError(f"--grid {text!r}: empty value in the list; {usage}")
    return name, [parse_value(name, v) for v in values]


def parse_value(name: str, text: str, number: bool = False):
    """Text as an int, else a float, else (unless ``number``) the string itself."""
    text = str(text).strip()
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    if number:
        raise SnapmemError(f"{name} = {text!r}: must be a number")
    return text


# ------------------------------------------------------------------------------------------
# running one design
def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (Integral, np.integer)):
        return str(int(value))
    if isinstance(value, (Real, np.floating)):
        value = float(value)
        return repr(value) if math.isfinite(value) else ""
    return " ".join(str(value).split())          # one line: newlines and tabs become spaces


def _call(function: Callable, design: dict) -> dict:
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
            outputs[str(name)] = _cell(value)
        return {"status": status, "message": _cell(message), "outputs": outputs}
    except SnapmemError as exc:
        return {"status": "invalid", "message": _cell(str(exc)), "outputs": {}}
    except Exception as exc:                                       # a failed design is a row
        return {"status": "error", "message": _cell(f"{type(exc).__name__}: {exc}"), "outputs": {}}


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
    """A pool worker: receive (index, design), send back the result of ``_call``, until EOF or
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
        conn.send(_call(function, task[1]))


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


def _call_isolated(function, design: dict, timeout: float | None) -> dict:
    """``_call`` in a forked child, killed after ``timeout`` seconds (for Dask workers, whose
    tasks run in threads that cannot be stopped, and so that a crash takes down only the child,
    as in the local pool). Inline where there is no fork."""
    if not hasattr(os, "fork"):
        return _call(function, design)
    _warm_up(function)
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:                                                   # child
        try:
            os.close(read_fd)
            data = pickle.dumps(_call(function, design))
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


# ------------------------------------------------------------------------------------------
# the output file
class _RowFile:
    """The CSV of a sweep: append-only while it runs, repaired after a kill, locked against a
    second sweep writing to it at the same time."""

    def __init__(self, path, names: list[str]):
        self.path = os.fspath(path)
        self.names = names
        self.outputs = None              # output column names, once the header is known
        self.done = {}                   # key -> design index of rows already in the file
        folder = os.path.dirname(os.path.abspath(self.path))
        if not os.path.isdir(folder):
            raise SnapmemError(f"out = {self.path!r}: folder {folder!r} does not exist")
        if os.path.isdir(self.path):
            raise SnapmemError(f"out = {self.path!r}: is a folder, must be a CSV file")
        try:
            self.fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise SnapmemError(f"out = {self.path!r}: cannot open ({exc.strerror})") from None
        try:
            import fcntl
            fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except ImportError:              # not POSIX: no lock
            pass
        except OSError:
            os.close(self.fd)
            raise SnapmemError(f"out = {self.path!r}: another sweep is writing to this file") from None
        try:
            self._read()
        except BaseException:
            os.close(self.fd)
            raise

    def _read(self):
        data = b""
        while True:
            chunk = os.pread(self.fd, 1 << 20, len(data))
            if not chunk:
                break
            data += chunk
        if data and not data.endswith(b"\n"):         # a line cut short by a kill: drop it
            keep = data.rfind(b"\n") + 1
            log.warning("%s: dropped a partial last line (%d bytes) left by an interrupted sweep",
                        self.path, len(data) - keep)
            os.ftruncate(self.fd, keep)
            os.fsync(self.fd)
            data = data[:keep]
        if not data:
            return
        try:
            rows = list(csv.reader(io.StringIO(data.decode("utf-8"))))
        except (UnicodeDecodeError, csv.Error) as exc:
            raise SnapmemError(f"out = {self.path!r}: not a sweep CSV ({exc})") from None
        header = rows[0]
        head = [*_LEADING, *self.names, "status"]
        if header[:len(head)] != head or header[-1:] != ["message"]:
            raise SnapmemError(f"out = {self.path!r}: has columns {', '.join(header)}; this sweep writes "
                               f"{', '.join(head)}, ..., message: resume with the same grid or choose a new file")
        self.outputs = header[len(head):-1]
        for line, row in enumerate(rows[1:], start=2):
            if len(row) != len(header):
                raise SnapmemError(f"out = {self.path!r}: line {line} has {len(row)} fields, the header "
                                   f"{len(header)}: the file is damaged; repair or remove that line")
            self.done.setdefault(row[1], row[0])

    @property
    def header(self) -> list[str]:
        return [*_LEADING, *self.names, "status", *self.outputs, "message"]

    def _write(self, rows: list[list[str]]):
        buffer = io.StringIO()
        csv.writer(buffer, lineterminator="\n").writerows(rows)
        view = memoryview(buffer.getvalue().encode("utf-8"))
        end = os.lseek(self.fd, 0, os.SEEK_END)
        while view:                                   # a kill between two writes leaves a partial line
            n = os.pwrite(self.fd, view, end)
            view, end = view[n:], end + n
        os.fsync(self.fd)

    def start(self, outputs: list[str]):
        """Write the header with these output columns (a new file)."""
        self.outputs = list(outputs)
        self._write([self.header])

    def append(self, index: int, key: str, design: dict, result: dict):
        """Append one finished design (outputs not in the header are named in the message)."""
        outputs = result["outputs"]
        extra = [name for name in outputs if name not in self.outputs]
        message = result["message"]
        if extra:
            message = (message + " " if message else "") + f"(outputs not in the file's columns, dropped: {', '.join(extra)})"
        row = [str(index), key, *(_cell(design[n]) for n in self.names), result["status"],
               *(outputs.get(n, "") for n in self.outputs), message]
        self._write([row])
        self.done[key] = str(index)

    def finish(self):
        """Rewrite the file in design order (atomically: a kill leaves the old file whole)."""
        with open(self.path, newline="", encoding="utf-8") as f:
            rows = list(csv.reader(f))
        if len(rows) <= 1:
            return
        rows[1:] = sorted(rows[1:], key=lambda row: (int(row[0]), row[1]))
        tmp = self.path + ".tmp"
        with open(tmp, "w", newline="", encoding="utf-8") as f:
            csv.writer(f, lineterminator="\n").writerows(rows)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.path)
        _fsync_folder(self.path)

    def close(self):
        os.close(self.fd)


def _fsync_folder(path):
    try:
        fd = os.open(os.path.dirname(os.path.abspath(path)), os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


# ------------------------------------------------------------------------------------------
# progress
class Progress:
    """A one-line progress bar on stderr: done/total, rate, time left, failures by status."""

    def __init__(self, total: int, done: int, enabled: bool = True, stream=None):
        self.total, self.done, self.start_done = total, done, done
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.tty = enabled and getattr(self.stream, "isatty", lambda: False)()
        self.statuses = Counter()
        self.t0 = self.last = time.monotonic()

    def update(self, status: str):
        self.done += 1
        self.statuses[status] += 1
        self.draw()

    def text(self) -> str:
        elapsed = time.monotonic() - self.t0
        ran = self.done - self.start_done
        rate = ran / elapsed if elapsed > 0 else 0.0
        left = (self.total - self.done) / rate if rate > 0 else float("inf")
        width = 24
        filled = int(width * self.done / self.total) if self.total else width
        failed = ", ".join(f"{n} {s}" for s, n in sorted(self.statuses.items()) if s in FAILED)
        return (f"sweep {self.done}/{self.total} [{'#' * filled}{'.' * (width - filled)}] "
                f"{rate:.1f} designs/s, {_duration(elapsed)} elapsed, {_duration(left)} left"
                + (f", {failed}" if failed else ""))

    def draw(self, force: bool = False):
        if not self.enabled:
            return
        now = time.monotonic()
        if not force and now - self.last < (0.2 if self.tty else 10.0):
            return
        self.last = now
        self.stream.write(("\r" + self.text() + "\033[K") if self.tty else self.text() + "\n")
        self.stream.flush()

    def close(self):
        if self.enabled:
            self.draw(force=True)
            if self.tty:
                self.stream.write("\n")
            self.stream.flush()


def _duration(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "?"
    seconds = int(round(seconds))
    h, rest = divmod(seconds, 3600)
    m, s = divmod(rest, 60)
    return f"{h}h{m:02d}m" if h else (f"{m}m{s:02d}s" if m else f"{s}s")


# ------------------------------------------------------------------------------------------
# executors: each yields (index, result) as designs finish
def _run_pool(function, tasks, workers: int, timeout: float | None):
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


def _run_dask(function, tasks, scheduler: str, workers: int, timeout: float | None):
    """The same designs as tasks on a Dask distributed cluster; each design still runs in
    ``_call`` (in a forked child when there is a time limit)."""
    from dask.distributed import as_completed
    client, cluster = _dask_client(scheduler, workers)
    try:
        futures = {}
        for index, design in tasks:
            future = client.submit(_call_isolated, function, design, timeout, pure=False)
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


# ------------------------------------------------------------------------------------------
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
        function's name), kept in ``<out>.sweep.json``: resuming with different ``meta`` (another
        job, other fixed parameters) is refused instead of mixing rows of two sweeps.

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
        clash = _RESERVED.union(names).intersection(columns)
        if clash:
            raise SnapmemError(f"columns: {sorted(clash)} clash with the design's parameters or the sweep's columns")

    if meta is None:
        meta = getattr(function, "meta", None)
    if meta is None:
        meta = {"function": f"{getattr(function, '__module__', '?')}.{getattr(function, '__qualname__', repr(function))}"}
    meta = json.loads(json.dumps(dict(meta), sort_keys=True, default=str))

    rows = _RowFile(out, names)
    try:
        _check_meta(rows.path, meta, fresh=rows.outputs is None and not rows.done)
        if rows.outputs is None and columns is not None:
            rows.start(columns)
        elif columns is not None and rows.outputs != columns:
            raise SnapmemError(f"out = {rows.path!r}: has outputs {', '.join(rows.outputs)}; this job writes "
                               f"{', '.join(columns)}: resume with the same job or choose a new file")
        todo = [(i, d) for i, (d, k) in enumerate(zip(designs, keys)) if k not in rows.done]
        resumed = len(designs) - len(todo)
        if resumed:
            log.info("%s: %d of %d designs already done, running %d", rows.path, resumed, len(designs), len(todo))
        bar = Progress(len(designs), resumed, enabled=progress)
        waiting = []                      # failed rows finished before the header is known
        if todo:
            run = (_run_pool(function, todo, workers, timeout) if scheduler is None
                   else _run_dask(function, todo, scheduler, workers, timeout))
            for index, result in run:
                if rows.outputs is None:
                    if result["status"] in FAILED and not result["outputs"]:
                        waiting.append((index, result))
                        bar.update(result["status"])
                        continue
                    rows.start(list(result["outputs"]))
                    for held in waiting:
                        rows.append(held[0], keys[held[0]], designs[held[0]], held[1])
                    waiting = []
                rows.append(index, keys[index], designs[index], result)
                bar.update(result["status"])
            if rows.outputs is None:
                rows.start([])
            for index, result in waiting:
                rows.append(index, keys[index], designs[index], result)
        bar.close()
        rows.finish()
    finally:
        rows.close()
    return read_rows(out)


def _check_meta(path: str, meta: dict, fresh: bool):
    """Write ``meta`` beside a new sweep file; refuse to resume one whose meta differs."""
    side = os.path.splitext(path)[0] + ".sweep.json"
    if not fresh and os.path.exists(side):
        try:
            with open(side, encoding="utf-8") as f:
                old = json.load(f)
        except (OSError, ValueError):
            old = None
        if old is not None and old != meta:
            changed = sorted(k for k in set(old) | set(meta) if old.get(k) != meta.get(k))
            raise SnapmemError(f"out = {path!r}: was written with {', '.join(f'{k} = {old.get(k)!r}' for k in changed)}; "
                               f"this sweep has {', '.join(f'{k} = {meta.get(k)!r}' for k in changed)}: "
                               "resume with the same settings or choose a new file")
        if old is not None:
            return
    tmp = side + ".tmp"
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(meta, f, indent=1, sort_keys=True)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, side)


def read_rows(path):
    """A sweep's CSV as a pandas DataFrame (parameters and outputs typed, empty cells NaN)."""
    import pandas as pd
    return pd.read_csv(path, dtype={"key": str, "status": str, "message": str}, keep_default_na=False,
                       na_values=[""])


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

