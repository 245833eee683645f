"""Time-stepping schemes, each a small object on the one backward-Euler solve of the stepper.

Every step of every scheme is the Newton solve of the incremental potential

    Pi(y, t*) + (1/2)(y - x_hat - h v_hat)^T M (y - x_hat - h v_hat) / h^2 + (1/2)(y - x_hat)^T C (y - x_hat) / h

(:class:`snapmem.dynamics.stepper._Stepper`). A scheme chooses what that solve is anchored at
(x_hat [m], v_hat [m/s]), its step h [s] and the time t* [s] of its loads (:meth:`Scheme.anchor`),
then turns the solution y into the new state (:meth:`Scheme.new_state`) and the step's
acceleration (:meth:`Scheme.acceleration`), and estimates the step's local error
(:meth:`Scheme.local_error`) for the adaptive step control. A scheme whose new state can leave
the admissible set (the midpoint rule's extrapolation) names a ``fallback`` that retakes such a
step. A new scheme is one more class here and one more entry in :data:`SCHEME_BY_NAME`.

The error estimates are (dt^2 / 2) |a_{n+1}| for implicit Euler (its local error) and a third
difference c dt^2 |a_{n+1} - a_n| (~ dt^3 q''' c) for the second-order schemes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from snapmem.dynamics.step_arithmetic import (BDF2 as BDF2_KIND, EULER, MIDPOINT, MIDPOINT_RULE, bdf2_anchor,
                                              largest_change, largest_entry, scheme_step, step_outcome)
from snapmem.dynamics.step_control import error_estimate
from snapmem.kernels.switch import compiled
from snapmem.solvers.rules import _max_abs_numpy

_KERNELS = {kernel.__name__: kernel for kernel in (bdf2_anchor, largest_change, largest_entry, step_outcome)}


def _kernel(name: str):
    """A kernel of snapmem.dynamics.step_arithmetic (its Python on the reference path): once it has
    compiled or loaded, its numba dispatcher itself, not the lazy stand-in's call in front of it;
    before, the stand-in, which decides (while numba's cache lacks the kernel it runs as Python,
    ``interpret_uncached``: a cold ``simulate`` compiles only the time step)."""
    kernel = _KERNELS[name]
    if not compiled():
        return kernel.py_func
    dispatcher = getattr(kernel, "_dispatcher", None)
    return kernel if dispatcher is None else dispatcher


_FLOAT64 = np.dtype(np.float64)


def _states(*arrays) -> bool:
    """Whether the arrays are what the kernels take: 1-d float arrays (a run's states; the
    numpy expressions, with the same numbers, take any other shape). A loop: it runs at every step."""
    for a in arrays:
        if type(a) is not np.ndarray or a.ndim != 1 or a.dtype != _FLOAT64:
            return False
    return True


def _indices(free) -> bool:
    """Whether ``free`` is an integer index array (a run's free degrees of freedom)."""
    return type(free) is np.ndarray and free.dtype.kind == "i"


@dataclass(frozen=True)
class Anchor:
    """The backward-Euler solve a scheme asks for in one time step.

    Attributes
    ----------
    scheme : Scheme
        The scheme that turns the solution into the new state (BDF2's first step: Euler's).
    q, v : ndarray (n_dof,)
        Position x_hat [m] and velocity v_hat [m/s] the inertia term is anchored at.
    h : float
        Step of the incremental potential [s].
    dt : float
        The time step [s].
    load_time : float
        Time at which the loads are evaluated [s].
    start : ndarray (n_dof,) or None
        Admissible Newton start when the predictor q + h v is not (None: ``q``).
    outcome : tuple or None
        (kind, step) of the step's outcome in snapmem.dynamics.step_arithmetic.step_outcome
        (:meth:`Scheme.compiled_outcome`).
    """

    scheme: Scheme
    q: np.ndarray
    v: np.ndarray
    h: float
    dt: float
    load_time: float
    start: np.ndarray | None = None
    outcome: tuple | None = None

    def new_state(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(q_{n+1}, v_{n+1}) from the solve's solution y."""
        return self.scheme.new_state(self, y)

    def acceleration(self, v_new: np.ndarray) -> np.ndarray:
        """The step's acceleration [m/s^2] that the error estimate compares."""
        return self.scheme.acceleration(self, v_new)


class Scheme:
    """A time-stepping scheme on the stepper's backward-Euler solve.

    Attributes
    ----------
    name : str
        The name ``DynamicsOptions.scheme`` and the CLI's ``--scheme`` take.
    kind : int
        Its number in snapmem.dynamics.step_arithmetic (EULER, MIDPOINT_RULE, BDF2), whose
        ``scheme_step`` holds its formulas for this class and the compiled run alike.
    order : int
        Order of accuracy; the step controller scales steps by err^(-1 / (order + 1)).
    error_constant : float
        c of the local error estimate c dt^2 |change of acceleration|.
    fallback : Scheme or None
        Retakes a step whose new state is inadmissible (None: the state is Newton's own, always
        admissible).
    """

    name: str
    kind: int
    order: int
    error_constant: float
    fallback: Scheme | None = None

    def anchor(self, q: np.ndarray, v: np.ndarray, t: float, dt: float, history) -> Anchor:
        """The solve of the step from (q, v) at time t [s] by dt [s]; ``history`` is
        (q_{n-1}, v_{n-1}, dt_{n-1}) of the previous accepted step, or None before the first."""
        raise NotImplementedError

    def new_state(self, anchor: Anchor, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def rest_coefficients(self, dt: float, past_dt: float | None) -> tuple:
        """The step's maps on a state at rest (no velocity: the viscous networks' internal
        stretches), (h, c_now, c_previous, n_star, n_now, n_previous): the step h [s], the
        anchor x_hat = c_now x_n + c_previous x_{n-1} and the new state x_{n+1} = n_star y +
        n_now x_n + n_previous x_{n-1}; ``past_dt`` the last step [s] (None: no history). The
        numbers :meth:`anchor` and :meth:`new_state` give on unit states, without building them."""
        h, *_, c_now, c_previous, n_star, n_now, n_previous = scheme_step(self.kind, 0.0, dt, past_dt)
        return float(h), c_now, c_previous, n_star, n_now, n_previous

    def acceleration(self, anchor: Anchor, v_new: np.ndarray) -> np.ndarray:
        """The mean acceleration over the step (v_{n+1} - v_n) / dt [m/s^2]."""
        return (v_new - anchor.v) / anchor.dt

    def local_error(self, dt: float, a_new: np.ndarray, a_prev: np.ndarray, free) -> float:
        """Local error estimate of a second-order scheme, c dt^2 max |a_new - a_prev| over the
        free degrees of freedom [m]."""
        if _states(a_new, a_prev) and _indices(free):
            change = _kernel("largest_change")(a_new, a_prev, free)
        else:
            change = np.abs(a_new - a_prev)[free].max()
        return self.estimate(dt, change)

    def estimate(self, dt: float, change) -> float:
        """c dt^2 ``change`` [m]: the local error estimate from the largest change of acceleration
        (Euler: the largest acceleration) [m/s^2]."""
        return error_estimate(self.error_constant, dt, float(change))

    def compiled_outcome(self, anchor: Anchor) -> tuple | None:
        """(kind, step) of this scheme's step in snapmem.dynamics.step_arithmetic.step_outcome, the
        compiled form of :meth:`new_state`, :meth:`acceleration` and :meth:`local_error` together
        (the compiled time step computes it too); None if the scheme has none."""
        return anchor.outcome

    def outcome(self, anchor: Anchor, y: np.ndarray, a_prev: np.ndarray, free, n_node_dofs: int) -> tuple:
        """Everything a step yields from the solve's solution y: (q_{n+1}, v_{n+1}, a_{n+1}, the local
        error estimate [m], max |q_i| over the first ``n_node_dofs`` entries (the membrane's size)
        [m]); ``a_prev`` the last step's acceleration. One compiled pass (:meth:`compiled_outcome`)
        on a run's arrays; else :meth:`new_state`, :meth:`acceleration` and :meth:`local_error`."""
        form = self.compiled_outcome(anchor)
        if form is not None and _states(y, anchor.q, anchor.v, a_prev) and _indices(free):
            kind, step = form
            q_new, v_new, a_new, change, largest = _kernel("step_outcome")(kind, y, anchor.q, anchor.v, anchor.h,
                                                                           step, a_prev, free, n_node_dofs)
            return q_new if kind == MIDPOINT else y, v_new, a_new, self.estimate(anchor.dt, change), float(largest)
        q_new, v_new = self.new_state(anchor, y)
        a_new = self.acceleration(anchor, v_new)
        return (q_new, v_new, a_new, self.local_error(anchor.dt, a_new, a_prev, free),
                _max_abs_numpy(q_new[:n_node_dofs]))


class ImplicitEuler(Scheme):
    """Implicit (backward) Euler, the paper's scheme: y = q_{n+1}, h = dt, loads at t_{n+1}.

    First order; it damps numerically (amplitude loss ~ (omega dt)^2 / 2 per step). Its state is
    Newton's own, so it never penetrates a contact.
    """

    name, kind, order, error_constant = "euler", EULER, 1, 0.5

    def anchor(self, q, v, t, dt, history):
        h, load_time, kind, step = scheme_step(EULER, t, dt, None)[:4]
        return Anchor(self, q, v, h, dt, load_time, outcome=(kind, step))

    def new_state(self, anchor, y):
        return y, (y - anchor.q) / anchor.h

    def local_error(self, dt, a_new, a_prev, free):
        """(dt^2 / 2) max |a_new| over the free degrees of freedom [m]: Euler's local error."""
        if _states(a_new) and _indices(free):
            change = _kernel("largest_entry")(a_new, free)
        else:
            change = np.abs(a_new)[free].max()
        return self.estimate(dt, change)



class ImplicitMidpoint(Scheme):
    """The implicit midpoint rule (the default).

    Solving the backward-Euler problem with h = dt / 2 and loads at t_n + dt / 2 gives the
    midpoint y = (q_n + q_{n+1}) / 2 exactly (substitute q_{n+1} = 2 y - q_n,
    v_{n+1} = 2 (y - q_n) / h - v_n into the midpoint rule); then extrapolate. Chosen over BDF2,
    Newmark and generalised-alpha because it is second order, symplectic (no numerical damping:
    the energy of an undamped oscillation stays bounded over long runs, which the drift test
    checks) and needs nothing but the backward-Euler solve, one step of history and no start-up
    procedure. Its lack of high-frequency dissipation is covered by the physical damping xi.
    The extrapolation 2 y - q_n can cross a contact gap even though y does not (a node arriving
    at a body): such a step is taken by implicit Euler instead (its ``fallback``; its state is
    Newton's own, so it never penetrates), counted in ``meta['euler_fallbacks']``. Its error
    estimate is (dt^2 / 6) |a_{n+1/2} - a_{n-1/2}|.
    """

    name, kind, order, error_constant = "midpoint", MIDPOINT_RULE, 2, 1.0 / 6.0

    def __init__(self, fallback: Scheme):
        self.fallback = fallback

    def anchor(self, q, v, t, dt, history):
        h, load_time, kind, step = scheme_step(MIDPOINT_RULE, t, dt, None)[:4]
        return Anchor(self, q, v, h, dt, load_time, outcome=(kind, step))

    def new_state(self, anchor, y):
        q, v, h = anchor.q, anchor.v, anchor.h
        return 2.0 * y - q, 2.0 * (y - q) / h - v


class BDF2(Scheme):
    """Variable-step BDF2 (the robotic scenes use it).

    With w = dt_n / dt_{n-1}, a0 = (1 + 2w) / (1 + w), h = dt / a0,
    x_hat = ((1 + w) q_n - w^2/(1 + w) q_{n-1}) / a0 and v_hat likewise from the velocities,
    y = q_{n+1} solves the incremental potential from (x_hat, v_hat) with step h; then
    v_{n+1} = (y - x_hat) / h and a_{n+1} = (v_{n+1} - v_hat) / h. Second order and L-stable: it
    damps the membrane's unresolved high-frequency ringing after a snap or an impact (which the
    midpoint rule keeps, forcing tiny steps), and its state is Newton's own, so contact never
    needs a fallback. Its first step (no history yet) is implicit Euler (``start``). Its error
    estimate is (2 dt^2 / 9) |a_{n+1} - a_n|.
    """

    name, kind, order, error_constant = "bdf2", BDF2_KIND, 2, 2.0 / 9.0

    def __init__(self, start: Scheme):
        self.start = start

    def anchor(self, q, v, t, dt, history):
        if history is None:
            return self.start.anchor(q, v, t, dt, history)
        h, load_time, kind, step, a0, a1, a2 = scheme_step(BDF2_KIND, t, dt, history[2])[:7]
        if _states(q, v, history[0], history[1]):
            x_hat, v_hat = _kernel("bdf2_anchor")(q, v, history[0], history[1], float(a0), float(a1), float(a2))
        else:
            x_hat = -(a1 * q + a2 * history[0]) / a0
            v_hat = -(a1 * v + a2 * history[1]) / a0
        return Anchor(self, x_hat, v_hat, h, dt, load_time, start=q, outcome=(kind, step))

    @staticmethod
    def weights(dt: float, past_dt: float) -> tuple:
        """(a0, a1, a2) of the variable step (w = dt / past_dt)."""
        return scheme_step(BDF2_KIND, 0.0, dt, past_dt)[4:7]

    def new_state(self, anchor, y):
        return y, (y - anchor.q) / anchor.h

    def rest_coefficients(self, dt, past_dt):
        if past_dt is None:
            return self.start.rest_coefficients(dt, past_dt)
        return super().rest_coefficients(dt, past_dt)

    def acceleration(self, anchor, v_new):
        """a_{n+1} = (v_{n+1} - v_hat) / h [m/s^2]."""
        return (v_new - anchor.v) / anchor.h


_EULER = ImplicitEuler()

SCHEME_BY_NAME: dict[str, Scheme] = {scheme.name: scheme for scheme in
                                     (ImplicitMidpoint(fallback=_EULER), BDF2(start=_EULER), _EULER)}
"""Every scheme by its name; the first is the default."""

SCHEMES = tuple(SCHEME_BY_NAME)
"""The schemes' names, e.g. for the CLI's choices."""
