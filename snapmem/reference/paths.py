"""Equilibria at values chosen in advance: a curve point by point, and Richardson's extrapolation.

:func:`snapmem.continuation.tracer.trace` finds a branch's points itself (arclength steps), its
stability at every point and its critical points. When the points are given instead (the loads
or the shapes at which a curve is wanted, as a shooting method or a volume-controlled FE code
computes it), a path is just one warm-started Newton solve per value, with no eigenvalues and no
step control:

* :func:`load_path`: equilibria at the given values of a load (pressure, voltage);
* :func:`coordinate_path`: equilibria with one coordinate of the meridian prescribed (the outer
  radius of a torus, the equator radius of a balloon) and the load the unknown, a Lagrange
  multiplier, as under volume control: this passes the load's limit points.

Each solve starts from the quadratic extrapolation of the states before it. The curve is only
as good as the mesh: :func:`extrapolate` combines the same curve on two or three meshes into one
whose error falls faster than N^-2 (Richardson).

A path does band solves and vector operations only (no dense blocks, no eigenvalues), so it does
not run under :func:`snapmem.threads.single_threaded`: it runs as fast without it (timings:
docs/performance.md).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from snapmem.errors import SnapmemError, SolverError
from snapmem.solvers.newton import NewtonOptions, newton, solve, start_guess
from snapmem.model.scene import Evaluation, Scene


@dataclass
class LoadPath:
    """States of a scene at the values of a load or coordinate path, in order.

    Attributes
    ----------
    q : ndarray (M, n_dof)
        The states.
    loads : ndarray (M,)
        The load at each state (the prescribed value for a load path, the solved one for a
        coordinate path).
    values : ndarray (M,)
        The prescribed values.
    iterations : int
        Newton iterations (linear solves) of the whole path.
    """

    q: np.ndarray
    loads: np.ndarray
    values: np.ndarray
    iterations: int


def _extrapolate_states(history, value):
    """Polynomial extrapolation to ``value`` through the (value, state) pairs of ``history`` (two
    or three: linear or quadratic, so the corrector starts O(step^3) from the curve)."""
    v = [h[0] for h in history]
    guess = 0.0
    for i, (vi, xi) in enumerate(history):          # Lagrange weights
        w = 1.0
        for j, vj in enumerate(v):
            if j != i:
                w *= (value - vj) / (vi - vj)
        guess = guess + w * xi
    return guess


class _Follower:
    """Solves along a path. The first value from ``first(value)`` (a prediction from the start
    state; the start itself if None); every next one from the extrapolation of the states before
    it, given up after ``PREDICTED_ITERATIONS`` Newton iterations or a step halved
    ``PREDICTED_CUTS`` times (a good prediction converges in two to four full steps), then from
    the last state. If that fails too, the step is halved (at most ``MAX_HALVINGS`` times), the
    intermediate states kept as history but not returned.

    ``solve_at(value, guess, options)`` returns (state, NewtonReport); guess None: the first solve
    of a path with no start state.
    """

    MAX_HALVINGS = 8
    PREDICTED_ITERATIONS = 8
    PREDICTED_CUTS = 3

    def __init__(self, solve_at, history, what, options: NewtonOptions, first=None):
        self.solve_at, self.history, self.what, self.options = solve_at, list(history), what, options
        self.first = first
        self.predicted = replace(options, max_iterations=min(options.max_iterations, self.PREDICTED_ITERATIONS),
                                 max_cuts=min(options.max_cuts, self.PREDICTED_CUTS))
        self.iterations = 0

    def guesses(self, value):
        if not self.history:
            return [(None, self.options)]
        if len(self.history) == 1:        # from the start: a spike of it may converge anywhere (an
            predicted = None if self.first is None else self.first(value)        # everted balloon)
            return [(self.history[0][1].copy() if predicted is None else predicted, self.options)]
        return [(_extrapolate_states(self.history, value), self.predicted), (self.history[-1][1].copy(), self.options)]

    def reach(self, value, halvings=MAX_HALVINGS):
        for guess, options in self.guesses(value):
            state, report = self.solve_at(value, guess, options)
            self.iterations += report.iterations
            if report.converged:
                self.history = [h for h in self.history[-2:] if h[0] != value] + [(value, state)]
                return state
        if not self.history or halvings == 0:
            raise SolverError(f"{self.what} = {value:.8g}: Newton failed ({report.reason}, "
                              f"|R| = {report.residual_norm:.2e})")
        self.reach(0.5 * (self.history[-1][0] + value), halvings - 1)
        return self.reach(value, halvings - 1)


def load_path(scene: Scene, values, load: str = "pressure", q0: np.ndarray | None = None,
              options: NewtonOptions = NewtonOptions()) -> LoadPath:
    """Equilibria of ``scene`` at load = each of ``values`` (in order), one Newton solve each.

    The first solve starts from ``q0`` (default: the scene's start guess at that load), each next
    one from the quadratic extrapolation of the states before it (see :class:`_Follower` for
    what happens when Newton fails from there). No stability, no limit points: a path in a load
    cannot pass its limit point (use :func:`coordinate_path` or continuation there).

    Raises
    ------
    SolverError
        If a solve fails (a value beyond a limit point, or a step too large for Newton).
    """
    values = np.asarray(values, dtype=float)
    base = scene.resolve_loads(None)
    if load not in base:
        raise SnapmemError(f"load {load!r}: scene {scene.name!r} has no such load; it has {sorted(base)}")

    def solve_at(value, guess, options):
        loads = {**base, load: float(value)}
        if guess is None:
            guess = q0 if q0 is not None else start_guess(scene, loads)
        eq = solve(scene, loads, q0=guess, options=options)
        return eq.q, eq.report

    follow = _Follower(solve_at, [], load, options)
    states = [follow.reach(value) for value in values]
    return LoadPath(np.array(states), values.copy(), values.copy(), follow.iterations)


def coordinate_path(scene: Scene, dof: int, values, start: tuple, load: str = "pressure",
                    options: NewtonOptions = NewtonOptions()) -> LoadPath:
    """Equilibria with coordinate q[dof] = each of ``values`` (in order), the load unknown.

    The unknowns are the free coordinates and the load; the equations R(q, load) = 0 on every
    free degree of freedom and q[dof] = value. Every iterate has q[dof] = value exactly, so the
    Jacobian is K with the prescribed row and column replaced by the identity's (a symmetric band
    matrix), bordered by dR/dload and K's prescribed row: regular where the load has a
    limit point along the path (K singular) as long as the coordinate keeps growing there, so
    the path passes pressure maxima as shooting in a shape parameter does. Each solve is damped
    Newton (:func:`snapmem.solvers.newton.newton`: the same domain checks and line search as any solve),
    started as in :func:`load_path`.

    Parameters
    ----------
    dof : int
        A free degree of freedom of the scene (index into q, e.g. 0 for a torus's outer radius).
    start : (q, loads)
        An equilibrium to start from (e.g. the reference state, unloaded); the first value is
        predicted along its tangent dq/dload = -K^-1 dR/dload (K must be regular there).

    Raises
    ------
    SolverError
        If a solve fails.
    """
    values = np.asarray(values, dtype=float)
    if scene.bodies:
        raise SnapmemError(f"coordinate_path: scene {scene.name!r} has rigid bodies (a bordered stiffness); "
                           "not supported")
    position = np.flatnonzero(scene.free == dof)
    if position.size != 1:
        raise SnapmemError(f"dof = {dof}: not a free degree of freedom of scene {scene.name!r}")
    k = int(position[0])
    q, loads = start
    loads = scene.resolve_loads(loads)
    if load not in loads:
        raise SnapmemError(f"load {load!r}: scene {scene.name!r} has no such load; it has {sorted(loads)}")
    n_dof, n = q.size, scene.n_free
    free = np.append(scene.free, n_dof)                 # the load is the last unknown
    tol = options.tol * scene.force_scale
    unit = _UnitRow(scene.bandwidth, n, k)

    def solve_at(value, guess, options):
        def evaluate(z):
            at = {**loads, load: float(z[-1])}
            ev = scene.evaluate(z[:-1], at, order=2)
            F = np.empty(n + 1)
            F[:n] = ev.residual
            F[n], F[k] = F[k], z[dof] - value
            return Evaluation(ev.energy, None, F, _Bordered(scene, z, at, load, ev.stiffness, unit), ev.residual_floor)

        guess[dof] = value
        z, _, report = newton(evaluate, guess, free, tol, options,
                              lambda z: scene.inadmissible(z[:-1]), lambda z, dz: scene.max_step(z[:-1], dz[:-1]))
        return z, report

    def first(value):
        """Euler prediction from the start: along dq/dload = -K^-1 dR/dload to q[dof] = value."""
        lu = scene.evaluate(q, loads, order=2).stiffness.factor()
        if lu.singular:
            return None
        rate = -lu.solve(scene.load_derivative(q, load, loads))
        if not np.all(np.isfinite(rate)) or rate[k] == 0.0:
            return None
        step = (value - q[dof]) / rate[k]
        guess = np.append(q, loads[load] + step)
        guess[scene.free] += step * rate
        return guess

    state = np.append(q, loads[load])
    follow = _Follower(solve_at, [(state[dof], state)], f"q[{dof}]", options, first)
    states = np.array([follow.reach(value) for value in values])
    return LoadPath(states[:, :n_dof], states[:, -1], values.copy(), follow.iterations)


class _Bordered:
    """The Jacobian of a coordinate path, [[A, b], [c^T, d]]: A = K with row and column k taken
    out (the identity's there), b = dR/dload (0 at k), c = K's row k, d = dR_k/dload.

    Built when factorised (Newton's last evaluation, at the converged state, needs none) and
    solved by block elimination, two band solves per right-hand side. The general
    :class:`snapmem.kernels.banded.BorderedMatrix` adds a refinement step for a singular A (K at a
    fold); this A stays regular at the load's limit point, so the plain elimination is accurate.
    """

    def __init__(self, scene, z, loads, load, K, unit):
        self.scene, self.z, self.loads, self.load, self.K, self.unit = scene, z, loads, load, K, unit

    def factor(self):
        return _BorderedLU(self)


class _BorderedLU:
    def __init__(self, M: _Bordered):
        k = M.unit.k
        b = M.scene.load_derivative(M.z[:-1], M.load, M.loads)
        d, b[k] = b[k], 0.0
        self.c = M.unit.take(M.K)
        self.inner = M.K.factor()
        self.z = self.inner.solve(b)
        self.schur = d - float(self.c @ self.z)
        self.singular = bool(self.inner.singular or self.schur == 0.0 or not np.isfinite(self.schur))

    def solve(self, rhs):
        y = self.inner.solve(rhs[:-1])
        x = np.empty(y.size + 1)
        x[-1] = mu = (rhs[-1] - float(self.c @ y)) / self.schur
        x[:-1] = y - mu * self.z
        return x


class _UnitRow:
    """Where row and column k of a symmetric band matrix (order n, half-bandwidth b) are stored."""

    def __init__(self, b: int, n: int, k: int):
        left = np.arange(max(0, k - b), k + 1)                # K[k, j] = lower[k - j, j], j <= k
        right = np.arange(k, min(n, k + b + 1))               # K[k, j] = lower[j - k, k], j >= k
        self.k, self.b = k, b
        self.left, self.right = (k - left, left), (right - k, np.full(right.size, k))
        self.dense = np.zeros(n)

    def take(self, K) -> np.ndarray:
        """Replace row and column k of K by the identity's (in place, K stays symmetric); return
        the old row k, dense."""
        lower = K.lower()
        row = self.dense.copy()
        row[self.left[1]] = lower[self.left]
        row[self.k + self.right[0]] = lower[self.right]
        lower[self.left] = 0.0
        lower[self.right] = 0.0
        lower[0, self.k] = 1.0
        return row


def extrapolate(h, values, log_term: bool = False) -> np.ndarray:
    """Richardson's extrapolation to h = 0 of a quantity computed on two or three meshes.

    Fits values(h) = v0 + a h^2 on two meshes, v0 + a h^2 + b h^4 on three (or, with
    ``log_term``, v0 + a h^2 + b h^2 log h: the error of a pole's node, whose observed order
    creeps up towards 2) and returns v0.

    Parameters
    ----------
    h : sequence of float
        Mesh sizes (any unit; only ratios matter).
    values : sequence of ndarray
        The quantity on each mesh (same shape each).
    """
    h = np.asarray(h, dtype=float) / max(h)
    if h.size not in (2, 3):
        raise SnapmemError(f"extrapolate: {h.size} meshes; need 2 or 3")
    columns = [np.ones_like(h), h ** 2]
    if h.size == 3:
        columns.append(h ** 2 * np.log(h) if log_term else h ** 4)
    weights = np.linalg.solve(np.stack(columns, axis=1).T, np.eye(h.size)[0])   # v0 = weights . values
    return sum(w * np.asarray(v, dtype=float) for w, v in zip(weights, values))
