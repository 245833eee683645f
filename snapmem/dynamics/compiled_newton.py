"""The compiled time step's Newton solve: damped Newton on the step's incremental potential, as
``snapmem.solvers.newton.newton(..., merit='energy')`` does it, with the same acceptance rules
(:mod:`snapmem.solvers.rules`), in one compiled call.

A solve ends with one of the codes below; :data:`OUTCOMES` gives each its
:class:`~snapmem.solvers.status.Status` and the report's reason.
"""

from __future__ import annotations

import numpy as np
from snapmem._lazy import njit

from snapmem.dynamics.compiled_assembly import (TANGENT, admissible, assemble, close_network_step, max_step,
                                                membrane_density, open_network_step, start_networks, state_ok)
from snapmem.dynamics.step_arithmetic import NO_OUTCOME, step_outcome
from snapmem.kernels.assembly import edge_stretches
from snapmem.kernels.bordered import band_solve, bordered_solve
from snapmem.kernels.linalg import REFINE_ON_CANCELLATION
from snapmem.solvers.rules import (CUT, converged, converged_at_end, energy_step_accepted, increment_error,
                                   inertia_tolerance, max_norm, moving_increment, step_length)
from snapmem.solvers.status import Status

#: How a compiled solve ends (an index into OUTCOMES), or HANDED_BACK: a step whose tangent the
#: LDL^T cannot take, for the general Newton (with its pivoted LU) to solve.
(CONVERGED, MAX_ITERATIONS, STEP_TOO_SMALL, LEFT_DOMAIN, SINGULAR, NOT_FINITE, START_OUTSIDE) = range(7)
HANDED_BACK = -1
#: (status, reason) of each code, as the Python Newton words them.
OUTCOMES = (
    (Status.converged, "converged"),
    (Status.max_iterations, "max iterations"),
    (Status.step_too_small, "line search failed: no step lowers the energy"),
    (Status.left_domain, "left the model's domain: every trial step was outside it"),
    (Status.singular, "singular tangent stiffness"),
    (Status.not_finite, "residual is not finite"),
    (Status.left_domain, "left the model's domain: the starting state is outside it"),
)


@njit(cache=True, nogil=True)
def time_step(anchor, velocity, h, mass, damping, fallback, P, general_law, linear, balls, viscous, network_step,
              pressure, a_el, tol, size, increment_tol, max_iterations, max_cuts, outcome_kind, outcome_step, a_previous):
    """One time step: its inertia M / h^2 + C / h, momentum M v / h and guess anchor + h v (on the
    free degrees of freedom; ``mass``, ``damping`` there), the tolerance kept above the inertia
    term's rounding floor (:func:`snapmem.solvers.rules.inertia_tolerance`), then damped Newton on
    the step's incremental potential: snapmem.solvers.newton.newton with merit='energy' (which
    documents every rule here). ``general_law``, ``linear``, ``balls``, ``viscous``: those terms or None
    (see :mod:`snapmem.dynamics.compiled_assembly`; the networks' local solves start at their
    anchor, :func:`start_networks`, and zeta*(y) is left in ``viscous.zeta_warm``). Returns (y, code, iterations, cuts, norm,
    *outcome), code one of this module's (an index into OUTCOMES, or HANDED_BACK), and, once
    converged, the scheme's outcome of the step (snapmem.dynamics.step_arithmetic.step_outcome of
    ``outcome_kind``, ``outcome_step`` and the last step's acceleration ``a_previous``): (q_{n+1},
    v_{n+1}, a_{n+1}, change, largest); (y, y, y, NaN, NaN) for NO_OUTCOME or an unconverged solve.

    One kernel, not a set-up calling a Newton kernel: numba optimises a kernel together with all
    it calls, so every level of calls is another pass over the whole solve at compile time.
    """
    free = P.free
    n = free.size
    inertia, momentum = np.empty(n), np.empty(n)
    for i in range(n):
        inertia[i] = mass[i] / (h * h) + damping[i] / h
        momentum[i] = mass[i] * velocity[free[i]] / h
    largest = -np.inf                          # np.max(inertia) (a loop: numba's np.max compiles a lot)
    for i in range(n):
        if np.isnan(inertia[i]):
            largest = inertia[i]
            break
        largest = max(largest, inertia[i])
    tol = inertia_tolerance(tol, largest, size)
    if viscous is not None:
        if network_step is not None:
            open_network_step(viscous, network_step)
        start_networks(viscous)
    guess = np.empty(anchor.size)              # anchor + h velocity (loops, not array expressions: numba
    for i in range(anchor.size):               # compiles each array expression as a function of its own)
        guess[i] = anchor[i] + h * velocity[i]
    if admissible(guess, P, general_law, linear, balls):
        q = guess.copy()
    else:
        q = fallback.copy()
        if not admissible(q, P, general_law, linear, balls):
            return q, START_OUTSIDE, 0, 0, np.nan, q, q, q, np.nan, np.nan
    energy, residual, lower, border, corner, floor = assemble(q, P, general_law, linear, balls, viscous, pressure,
                                                              a_el, inertia, anchor, momentum, TANGENT)
    norm = max_norm(residual)
    last_step = np.inf
    iterations = cuts = 0
    code = MAX_ITERATIONS
    dq = np.empty(q.size)                       # zeros (np.zeros is one more overload to compile)
    dq[:] = 0.0
    last_at_q = True                            # whether the last assembly was at q (the networks' zeta* is q's)
    rate, previous = 1.0, np.inf                # the increment test's contraction rate and last full step
    for _ in range(max_iterations):
        if converged(norm, tol, floor, last_step, q):
            code = CONVERGED
            break
        if not np.isfinite(norm):
            code = NOT_FINITE
            break
        rhs = np.empty(n)                           # -residual
        for i in range(n):
            rhs[i] = -residual[i]
        if balls is None:                           # no bodies (CompiledStep.terms): the band alone
            dx, ok = band_solve(lower, rhs)
        else:
            dx, ok = bordered_solve(lower, border, corner, rhs, REFINE_ON_CANCELLATION)
        if not ok:
            return q, HANDED_BACK, iterations, cuts, norm, q, q, q, np.nan, np.nan
        for i in range(free.size):
            dq[free[i]] = dx[i]
        alpha = min(1.0, max_step(q, dq, P, linear, balls))
        slope = residual @ dx
        iterations += 1
        accepted = inside = False
        trial = q
        e_t, r_t, lo_t, bo_t, co_t, fl_t, n_t = energy, residual, lower, border, corner, floor, norm
        for _cut in range(max_cuts + 1):
            trial = np.empty(q.size)                # q + alpha dq
            for i in range(q.size):
                trial[i] = q[i] + alpha * dq[i]
            inside = state_ok(trial, P, general_law)   # the contacts' gaps: the barriers' energy is inf at a gap <= 0
            if inside:
                e_t, r_t, lo_t, bo_t, co_t, fl_t = assemble(trial, P, general_law, linear, balls, viscous, pressure,
                                                            a_el, inertia, anchor, momentum, TANGENT)
                last_at_q = False
                inside = e_t < np.inf
                n_t = max_norm(r_t)
                if energy_step_accepted(e_t, n_t, energy, norm, alpha, slope):
                    accepted = True
                    break
            alpha *= CUT
            cuts += 1
        if not accepted:
            code = STEP_TOO_SMALL if inside else LEFT_DOMAIN
            break
        q, energy, residual, lower, border, corner, floor = trial, e_t, r_t, lo_t, bo_t, co_t, fl_t
        norm = n_t
        last_at_q = True
        last_step = step_length(alpha, dx)
        if increment_tol > 0.0:
            if alpha == 1.0:
                increment = moving_increment(dx, mass)
                rate, error = increment_error(increment, previous, rate)
                previous = increment
                if error <= increment_tol:
                    code = CONVERGED
                    break
            else:
                previous = np.inf
    if code != CONVERGED and converged_at_end(norm, tol, floor):
        code = CONVERGED
    if viscous is not None and not last_at_q:      # the last assembly was a rejected trial: zeta* at q again
        lam1, lam2 = edge_stretches(q, P.edges, P.inv_length, P.inv_mid_radius)
        membrane_density(lam1, lam2, P, general_law, viscous, 0.0)
    if viscous is not None and network_step is not None and code == CONVERGED:
        close_network_step(viscous, network_step, P.weight)
    if outcome_kind == NO_OUTCOME or code != CONVERGED:
        return q, code, iterations, cuts, norm, q, q, q, np.nan, np.nan
    q_new, v_new, a_new, change, largest = step_outcome(outcome_kind, q, anchor, velocity, h, outcome_step, a_previous,
                                                        free, P.n_node_dofs)
    return q, code, iterations, cuts, norm, q_new, v_new, a_new, change, largest
