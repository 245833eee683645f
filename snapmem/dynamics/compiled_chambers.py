"""A time step of several membranes on shared chambers, its whole Newton solve in one compiled call.

The numpy step (:class:`snapmem.dynamics.supplies.ChamberStepper`, whose module docstring gives
the equations) solves, for the stacked positions y of every membrane and the pressures p of the
chambers that hold a fluid or a gas,

    R_i(y_i; s_i p) + inertia_i (y_i - x_hat_i) - momentum_i = 0      (every membrane i)
    -s (V_c(y) - V_c*(p_c)) = 0                                     (every such chamber)

by Newton with the 'residual' merit (Armijo on |R|^2). This kernel does the same, with the same
rules (:mod:`snapmem.solvers.rules`), in one call: every membrane's incremental potential by the
single-meridian step's assembly (:func:`snapmem.dynamics.compiled_assembly.assemble`: the same
law, electric and pressure kernels as ``Scene.evaluate``), the chambers' volumes and gradients by
the swept-volume kernels, their targets V_c*(p) by :func:`chamber_target` (which the numpy step
calls too), and the membranes' bands stacked side by side into one band bordered by one row and
column per chamber, solved by :func:`snapmem.kernels.bordered.bordered_solve` (O(N) per
membrane). The chamber rows are divided by their scale s before the solve, which makes the
bordered matrix symmetric, [[K, -G], [-G^T, -D]]: the same Newton direction.

What it covers (:meth:`ChamberCompiledStep.of` returns None otherwise, and the numpy step runs):
membranes whose terms all declare a compiled form (:mod:`snapmem.dynamics.compiled_step`) without
rigid bodies or viscous networks, with linear-gap contacts on all or none of them, and chambers of
prescribed pressure, fluid (prescribed volume, flow source, resistance-fed) or isothermal gas. A
step whose band the LDL^T cannot factor stably is handed back to the numpy step.
"""

from __future__ import annotations

import numpy as np
from snapmem._lazy import njit

from snapmem.dynamics.compiled_assembly import COMPILED_ONLY, TANGENT, GeneralLaw, admissible, assemble, max_step
from snapmem.dynamics.compiled_newton import (CONVERGED, HANDED_BACK, LEFT_DOMAIN, MAX_ITERATIONS, NOT_FINITE,
                                              OUTCOMES, START_OUTSIDE, STEP_TOO_SMALL)
from snapmem.dynamics.compiled_step import CompiledStep
from snapmem.kernels.assembly import swept_volume, volume_gradient
from snapmem.kernels.bordered import bordered_solve
from snapmem.kernels.laws import LAW_LINEAR
from snapmem.kernels.linalg import REFINE_ALWAYS
from snapmem.solvers.newton import NewtonReport
from snapmem.solvers.rules import (CUT, converged, converged_at_end, max_norm, residual_step_accepted,
                                   step_length)
from snapmem.solvers.status import Status

#: What fills a chamber whose pressure is an unknown (:func:`chamber_target`'s ``kind``):
#: a fluid of prescribed volume, a fluid fed through a resistance, an isothermal gas.
TARGET_VOLUME, TARGET_RESISTANCE, TARGET_GAS = 0, 1, 2
#: Parameters of a target, padded to this many.
TARGET_PARAMETERS = 4


@njit(cache=True, nogil=True)
def chamber_target(kind, params, p):
    """(V_c* [m^3], D = -dV_c*/dp [m^3/Pa]) of a chamber at pressure p [Pa]: what the chamber's
    filling prescribes (:mod:`snapmem.dynamics.supplies`). ``kind`` TARGET_VOLUME: params (V,);
    TARGET_RESISTANCE: (anchor x_hat [m^3], step h [s], source pressure p_s [Pa], resistance
    R_f [Pa s/m^3]), V* = x_hat + h (p_s - p) / R_f; TARGET_GAS: (n R T [J], p_atm [Pa]),
    V* = n R T / (p + p_atm)."""
    if kind == TARGET_GAS:
        absolute = p + params[1]
        return params[0] / absolute, params[0] / absolute ** 2
    if kind == TARGET_RESISTANCE:
        return params[0] + params[1] * (params[2] - p) / params[3], params[1] / params[3]
    return params[0], 0.0


@njit(**COMPILED_ONLY)
def _membrane(x, i, offsets):
    """Membrane i's part of the stacked state, as its own contiguous array. Compiled code only (COMPILED_ONLY)."""
    return x[offsets[i]: offsets[i + 1]].copy()


@njit(**COMPILED_ONLY)
def _volume(q, edges):
    """The swept volume of one meridian [m^3]. Compiled code only (COMPILED_ONLY)."""
    v = 0.0
    for e in range(edges.shape[0]):
        a, b = edges[e, 0], edges[e, 1]
        v += swept_volume(q[2 * a], q[2 * b], q[2 * b + 1] - q[2 * a + 1], 1.0)[0]
    return v


@njit(**COMPILED_ONLY)
def _inside(x, n, plans, laws, linears, offsets, mem_unknown, mem_sign, dead, kinds, tparams, pressures):
    """Whether x = (y, p) is inside the domain: every membrane's (MultiScene.inadmissible), a gas
    chamber's volume positive, and (``pressures``) its absolute pressure positive.
    Compiled code only (COMPILED_ONLY)."""
    k = dead.size
    volumes = dead.copy()
    for i in range(len(plans)):
        qi = _membrane(x, i, offsets)
        if linears is None:
            ok = admissible(qi, plans[i], laws[i], None, None)
        else:
            ok = admissible(qi, plans[i], laws[i], linears[i], None)
        if not ok:
            return False
        j = mem_unknown[i]
        if j >= 0 and kinds[j] == TARGET_GAS:
            volumes[j] += mem_sign[i] * _volume(qi, plans[i].edges)
    for j in range(k):
        if kinds[j] == TARGET_GAS:
            if not volumes[j] > 0.0:
                return False
            if pressures and not x[n + j] + tparams[j, 1] > 0.0:
                return False
    return True


@njit(**COMPILED_ONLY)
def _assemble_all(x, n, anchor, inertia, momentum, plans, laws, linears, a_el, mem_unknown, mem_sign, mem_pressure,
                  offsets, free_offsets, dead, kinds, tparams, row_scale, bandwidth):
    """Residual (N + k,) (the chamber rows scaled by ``row_scale``), stacked lower band (b + 1, N),
    border -G^T (k, N), corner -D (k, k) and rounding floor of the bordered step at x = (y, p).
    Compiled code only (COMPILED_ONLY)."""
    k = dead.size
    N = free_offsets[-1]
    residual = np.empty(N + k)
    lower = np.zeros((bandwidth + 1, N))
    border = np.zeros((k, N))
    corner = np.zeros((k, k))
    volumes = dead.copy()
    floor = 0.0
    for i in range(len(plans)):
        P = plans[i]
        fa, fb = free_offsets[i], free_offsets[i + 1]
        qi, anchor_i = _membrane(x, i, offsets), _membrane(anchor, i, offsets)
        inertia_i, momentum_i = inertia[fa:fb].copy(), momentum[fa:fb].copy()
        j = mem_unknown[i]
        pressure = mem_sign[i] * x[n + j] if j >= 0 else mem_pressure[i]
        if linears is None:
            _e, r, lo, _b, _c, fl = assemble(qi, P, laws[i], None, None, None, pressure, a_el[i], inertia_i, anchor_i,
                                             momentum_i, TANGENT)
        else:
            _e, r, lo, _b, _c, fl = assemble(qi, P, laws[i], linears[i], None, None, pressure, a_el[i], inertia_i,
                                             anchor_i, momentum_i, TANGENT)
        floor = max(floor, fl)
        nb = fb - fa
        for c in range(nb):
            residual[fa + c] = r[c]
        for d in range(lo.shape[0]):              # entries past the block stay 0 (as multi.stack_bands)
            for c in range(nb - d):
                lower[d, fa + c] = lo[d, c]
        if j >= 0:
            s = mem_sign[i]
            volumes[j] += s * _volume(qi, P.edges)
            g = volume_gradient(qi, P.edges, qi.size)
            for c in range(nb):
                border[j, fa + c] = -s * g[P.free[c]]
    for j in range(k):
        v_star, D = chamber_target(kinds[j], tparams[j], x[n + j])
        residual[N + j] = -row_scale * (volumes[j] - v_star)
        corner[j, j] = -D
    return residual, lower, border, corner, floor


@njit(cache=True, nogil=True)
def chamber_time_step(anchor, guess, fallback, pressure0, inertia, momentum, free, plans, laws, linears, a_el, mem_unknown,
                      mem_sign, mem_pressure, offsets, free_offsets, dead, kinds, tparams, row_scale, bandwidth, tol,
                      max_iterations, max_cuts):
    """One bordered time step (module docstring): Newton from (``guess``, or ``fallback`` if the
    guess is outside the membranes' domain, and ``pressure0``) with the
    rules of snapmem.solvers.newton.newton(merit='residual'), ``free`` the stacked free degrees of
    freedom, ``tol`` [N] the step's tolerance. Returns (x = (y, p), code, iterations, cuts, norm),
    code one of snapmem.dynamics.compiled_newton's (HANDED_BACK: the band's LDL^T failed)."""
    n, k = anchor.size, dead.size
    N = free.size
    x = np.empty(n + k)
    x[:n] = guess
    x[n:] = pressure0
    if not _inside(x, n, plans, laws, linears, offsets, mem_unknown, mem_sign, dead, kinds, tparams, False):
        x[:n] = fallback
    if not _inside(x, n, plans, laws, linears, offsets, mem_unknown, mem_sign, dead, kinds, tparams, True):
        return x, START_OUTSIDE, 0, 0, np.nan
    residual, lower, border, corner, floor = _assemble_all(x, n, anchor, inertia, momentum, plans, laws, linears, a_el,
                                                           mem_unknown, mem_sign, mem_pressure, offsets, free_offsets,
                                                           dead, kinds, tparams, row_scale, bandwidth)
    norm = max_norm(residual)
    last_step = np.inf
    iterations = cuts = 0
    code = MAX_ITERATIONS
    dq = np.zeros(n + k)
    rhs = np.empty(N + k)
    for _ in range(max_iterations):
        if converged(norm, tol, floor, last_step, x):
            code = CONVERGED
            break
        if not np.isfinite(norm):
            code = NOT_FINITE
            break
        for c in range(N):
            rhs[c] = -residual[c]
        for j in range(k):                       # the chamber rows unscaled: a symmetric bordering
            rhs[N + j] = -residual[N + j] / row_scale
        dx, ok = bordered_solve(lower, border, corner, rhs, REFINE_ALWAYS)
        if not ok:
            return x, HANDED_BACK, iterations, cuts, norm
        for c in range(N):
            dq[free[c]] = dx[c]
        for j in range(k):
            dq[n + j] = dx[N + j]
        alpha = 1.0
        for i in range(len(plans)):
            qi, dqi = _membrane(x, i, offsets), _membrane(dq, i, offsets)
            if linears is None:
                alpha = min(alpha, max_step(qi, dqi, plans[i], None, None))
            else:
                alpha = min(alpha, max_step(qi, dqi, plans[i], linears[i], None))
        squared = residual @ residual
        iterations += 1
        accepted = inside = False
        trial = x
        r_t, lo_t, bo_t, co_t, fl_t = residual, lower, border, corner, floor
        for _cut in range(max_cuts + 1):
            trial = x + alpha * dq
            inside = _inside(trial, n, plans, laws, linears, offsets, mem_unknown, mem_sign, dead, kinds, tparams, True)
            if inside:
                r_t, lo_t, bo_t, co_t, fl_t = _assemble_all(trial, n, anchor, inertia, momentum, plans, laws, linears,
                                                            a_el, mem_unknown, mem_sign, mem_pressure, offsets,
                                                            free_offsets, dead, kinds, tparams, row_scale, bandwidth)
                if residual_step_accepted(r_t @ r_t, squared, alpha):
                    accepted = True
                    break
            alpha *= CUT
            cuts += 1
        if not accepted:
            code = STEP_TOO_SMALL if inside else LEFT_DOMAIN
            break
        x, residual, lower, border, corner, floor = trial, r_t, lo_t, bo_t, co_t, fl_t
        norm = max_norm(residual)
        last_step = step_length(alpha, dx)
    if code != CONVERGED and converged_at_end(norm, tol, floor):
        code = CONVERGED
    return x, code, iterations, cuts, norm


#: The reports' (status, reason) of each code: the compiled Newton's, with the 'residual' merit's line search.
CHAMBER_OUTCOMES = tuple((Status.step_too_small, "line search failed: no step reduces the residual")
                         if code == STEP_TOO_SMALL else outcome for code, outcome in enumerate(OUTCOMES))


def _ints(values) -> np.ndarray:
    return np.ascontiguousarray(values, dtype=np.int64)


class ChamberCompiledStep:
    """The compiled bordered time step of a :class:`~snapmem.model.multi.MultiScene` (module
    docstring). Build with :meth:`of`; :meth:`solve` takes the place of the numpy Newton in
    :class:`snapmem.dynamics.supplies.ChamberStepper`."""

    def __init__(self, scene, steps: list, linears, multiplied: list):
        self.scene, self.steps = scene, steps
        self.plans = tuple(s.plan for s in steps)
        self.laws = tuple(s.terms[0] if s.terms[0] is not None else GeneralLaw(LAW_LINEAR, s.plan.law_params)
                          for s in steps)
        self.linears = linears
        self.multiplied = multiplied
        unknown = {c: j for j, c in enumerate(multiplied)}
        self.mem_unknown = _ints([-1 if scene.chamber_of[i] is None else unknown.get(scene.chamber_of[i][0], -1)
                                  for i in range(len(steps))])
        self.mem_sign = np.array([0.0 if own is None else float(own[1]) for own in scene.chamber_of])
        self.offsets = _ints(scene.offsets)
        self.free_offsets = _ints(scene.free_offsets)
        self.free = _ints(scene.free)
        self.dead = np.array([scene.chambers[c].dead_volume for c in multiplied], dtype=float)
        self.bandwidth = int(max(p.bandwidth for p in self.plans))

    @classmethod
    def of(cls, scene, multiplied: list) -> "ChamberCompiledStep | None":
        """The compiled step of ``scene`` (``multiplied``: its chambers whose pressure is an unknown),
        or None where it does not apply (module docstring) or on the reference path."""
        from snapmem.model.chambers import ChamberKind
        if any(scene.chambers[c].kind not in (ChamberKind.VOLUME, ChamberKind.GAS) for c in multiplied):
            return None
        steps = [CompiledStep.of(m) for m in scene.membranes]
        if any(s is None or s.viscous is not None or s.terms[2] is not None for s in steps):
            return None
        for i, (s, own) in enumerate(zip(steps, scene.chamber_of)):
            if own is not None and not s.has_pressure:        # a chamber's work other than the swept volume's
                return None
        linear = [s.terms[1] for s in steps]
        if all(c is None for c in linear):
            linears = None
        elif all(c is not None for c in linear):
            linears = tuple(linear)
        else:
            return None                                   # contacts on some membranes only: the numpy step
        return cls(scene, steps, linears, list(multiplied))

    def solve(self, anchor, guess, fallback, pressure0, inertia, momentum, loads, targets, row_scale, tol, options):
        """(y, pressures, NewtonReport) of the step, or None to hand it back to the numpy step.

        ``targets``: (kind, params) of every multiplied chamber (``ChamberState.target_parameters``);
        ``loads``: the scene's at the solve (prescribed pressures, voltages); the rest as
        :func:`chamber_time_step`."""
        scene = self.scene
        a_el = np.empty(len(self.steps))
        mem_pressure = np.zeros(len(self.steps))
        for i, (step, own) in enumerate(zip(self.steps, scene.chamber_of)):
            # a prescribed chamber pressure is a load; an unknown one is the kernel's (mem_unknown)
            pressure = 0.0 if own is None or self.mem_unknown[i] >= 0 else own[1] * loads[scene.pressure_name(own[0])]
            mem_pressure[i], a_el[i] = step.kernel_loads({"pressure": pressure, "voltage": loads.get(f"voltage_{i + 1}", 0.0)})
        k = len(self.multiplied)
        kinds = _ints([kind for kind, _ in targets]).reshape(k)
        tparams = np.zeros((k, TARGET_PARAMETERS))
        for j, (_, params) in enumerate(targets):
            tparams[j, : len(params)] = params
        x, code, iterations, cuts, norm = chamber_time_step(
            np.ascontiguousarray(anchor, dtype=float), np.ascontiguousarray(guess, dtype=float),
            np.ascontiguousarray(fallback, dtype=float),
            np.ascontiguousarray(pressure0, dtype=float), inertia, momentum, self.free, self.plans, self.laws,
            self.linears, a_el, self.mem_unknown, self.mem_sign, mem_pressure, self.offsets, self.free_offsets,
            self.dead, kinds, tparams, float(row_scale), self.bandwidth, float(tol), options.max_iterations,
            options.max_cuts)
        if code == HANDED_BACK:
            return None
        status, reason = CHAMBER_OUTCOMES[code]
        n = anchor.size
        report = NewtonReport(code == CONVERGED, int(iterations), float(norm), reason, int(cuts), status=status)
        return x[:n].copy(), x[n:].copy(), report
