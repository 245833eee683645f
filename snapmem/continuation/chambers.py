"""Continuation of multi-membrane scenes whose chambers hold a fluid or a gas.

The unknowns are the membranes' free degrees of freedom y and the pressure p_c of every chamber
with a multiplier (a fluid or a gas, :class:`~snapmem.model.chambers.Chamber`); the equations

    R(y; p) = 0                                  (each membrane under its chamber's pressure)
    -(V_c(y) - V_c*(p_c)) = 0                    (one per such chamber)

with V_c* the fluid volume (fluid), the gas' volume n R T / (p_c + p_atm) (gas) or
(C / (p_c + p_atm))^(1/gamma) (adiabatic gas). They are the
stationarity conditions of the Lagrangian L(y, p) = sum_i Pi_i(y_i; p) + sum_c p_c V_c*(p_c)
- E*_c(p_c): the Jacobian

    J = [[K, -G], [-G^T, -D]],     G = (dV_c/dy) (n, k),  D = diag(-dV_c*/dp_c) >= 0

is symmetric, the band K bordered by one row and column per chamber (O(N) per membrane). Its
elimination of p gives the Hessian of the total energy on the constraint set: K + G D^-1 G^T for
a gas (the gas' stiffness n R T / V^2 along grad V), K on G^T dy = 0 for a fluid. Haynsworth's
inertia formula counts that energy's negative eigenvalues exactly,

    neg = neg(K) + neg(S) - k,      S = -D - G^T K^-1 G  (k x k),

which is the stability reported. The eigenvalues watched (``min_eig``) are J's nearest zero: J is
singular exactly where the energy's Hessian is, and its null vector is that Hessian's (with the
pressure change it carries), so critical points are located and branches switched on J.

Controls: ``volume`` (the fluid chamber's volume [m^3]), ``gas_amount`` (n R T of the gas chamber
[J], or the adiabat's C = P V^gamma of an adiabatic one), ``pressure`` (a prescribed-pressure chamber's pressure [Pa]) and ``voltage_1``, ... (a
membrane's voltage [V]).
"""

from __future__ import annotations

import numpy as np

from snapmem.continuation.problems import PROBLEM_FACTORIES, LoadProblem
from snapmem.errors import SnapmemError
from snapmem.kernels.banded import BandedMatrix, BorderedMatrix, eigenvalues_near_zero, scale_of
from snapmem.kernels.linalg import REFINE_ON_CANCELLATION
from snapmem.model.chambers import ChamberKind, gas_compliance, gas_volume
from snapmem.model.multi import MultiScene

#: Controls of a multi-membrane scene besides the membranes' voltages ``voltage_1``, ...
CHAMBER_CONTROLS = ("volume", "gas_amount", "pressure")


class ChamberJacobian(BorderedMatrix):
    """J = [[K, -G], [-G^T, -D]] (module docstring): a :class:`BorderedMatrix` on a band K whose
    product with several vectors at once (the eigenvalue iterations' subspace) is one band product
    and two small dense ones, not one product per vector.

    Its solves refine only where the Schur complement shows cancellation
    (:data:`~snapmem.kernels.linalg.REFINE_ON_CANCELLATION`): every solve the tracer makes with it
    (corrector, tangent) goes through the arclength bordering around J, which refines always with
    the exact product J x, so a second refinement inside it only repeated that work (half of the
    band solves of a step). The traced branches agree with always refining to 1e-13 relative.
    """

    def matvec(self, x: np.ndarray) -> np.ndarray:
        if x.ndim == 1 or not isinstance(self.A, BandedMatrix):
            return super().matvec(x)
        n = self.A.n
        y = np.empty((self.n, x.shape[1]))
        y[:n] = self.A.matvec(x[:n])
        y[:n] += self.B @ x[n:]
        y[n:] = self.C.T @ x[:n] + self.D @ x[n:]
        return y

    def factor(self, inner=None, refine: int = REFINE_ON_CANCELLATION):
        return super().factor(inner, refine)


class ChamberProblem(LoadProblem):
    """Equilibria of a :class:`~snapmem.model.multi.MultiScene`: x = (free dofs, the pressures of
    the fluid and gas chambers), parameter ``control`` (see the module docstring)."""

    jacobian_is_stiffness = True        # J is singular exactly where the energy's Hessian is
    #: A crossing eigenvalue of J within this fraction of |J| is at its zero to rounding: locating a
    #: BP stops there (locate._crossing_ftol; the BPs of Brent's xtol alone to 1e-11, tests/test_chambers.py).
    crossing_rounding = float(np.finfo(float).eps)

    def __init__(self, scene: MultiScene, control: str):
        self.scene, self.control = scene, control
        self.base = scene.resolve_loads(None)
        self.multiplied = [c for c, ch in enumerate(scene.chambers) if ch.has_multiplier]
        self.load = None
        self.controlled = None
        kind = {"volume": ChamberKind.VOLUME, "gas_amount": ChamberKind.GAS, "pressure": ChamberKind.PRESSURE}
        if control in kind:
            found = [c for c, ch in enumerate(scene.chambers) if ch.kind is kind[control]
                     or (control == "gas_amount" and ch.is_gas)]
            if not found:
                raise SnapmemError(f"control = {control!r}: scene {scene.name!r} has no {kind[control].value} "
                                   f"chamber (it has {[ch.kind.value for ch in scene.chambers]})")
            self.controlled = found[0]
            if control == "pressure":
                self.load = scene.pressure_name(self.controlled)
        elif control in scene.loads and control.startswith("voltage_"):
            self.load = control
        else:
            raise SnapmemError(f"control = {control!r}: scene {scene.name!r} takes "
                               f"{', '.join(self._allowed())}")
        self.factor = 1.0
        L, N = scene.meridian.size, scene.meridian.nodes
        self.p_scale = scene.mu * scene.thickness / L
        self.x_weight = np.concatenate([np.full(scene.n_free, 1.0 / (L * L * N)),
                                        np.full(len(self.multiplied), 1.0 / self.p_scale ** 2)])
        q0 = self._reference = scene.reference_state()
        v0 = abs(scene.chamber_volume(q0, self.controlled)) if self.controlled is not None else 0.0
        v0 = v0 if v0 > 0 else L ** 3
        exponent = scene.chambers[self.controlled].exponent if self.controlled is not None else 1.0
        self.lam_scale = {"volume": 10.0 * v0, "pressure": self.p_scale,      # (an adiabat's C: P V^gamma)
                          "gas_amount": 10.0 * (v0 if exponent == 1.0 else v0 ** exponent) * self.p_scale
                          }.get(control, None)
        if self.lam_scale is None:        # a voltage
            self.lam_scale = scene.thickness * np.sqrt(scene.mu / (scene.permittivity or 1.0))
        # the fixed fluid volumes and gas amounts (None: as at the start, set by `unknowns`)
        self.fixed = {c: (scene.chambers[c].volume if scene.chambers[c].kind is ChamberKind.VOLUME
                          else scene.chambers[c].amount) for c in self.multiplied}

    def _allowed(self):
        kinds = {ChamberKind.GAS if ch.is_gas else ch.kind for ch in self.scene.chambers}
        out = [c for c, k in (("volume", ChamberKind.VOLUME), ("gas_amount", ChamberKind.GAS),
                              ("pressure", ChamberKind.PRESSURE)) if k in kinds]
        return out + [k for k in self.scene.loads if k.startswith("voltage_")]

    @property
    def n(self) -> int:
        return self.scene.n_free + len(self.multiplied)

    # ----------------------------------------------------------------------------------------
    def state(self, x, lam):
        sc = self.scene
        q = self._reference.copy()
        q[sc.free] = x[: sc.n_free]
        loads = dict(self.base)
        for j, c in enumerate(self.multiplied):
            loads[sc.pressure_name(c)] = float(x[sc.n_free + j])
        if self.load is not None:
            loads[self.load] = float(lam)
        return q, loads

    def x_of(self, q, loads=None):
        loads = self.base if loads is None else loads
        return np.concatenate([q[self.scene.free],
                               [loads[self.scene.pressure_name(c)] for c in self.multiplied]])

    def target(self, c: int, pressure: float, lam: float):
        """(V_c* [m^3], its derivative dV_c*/dp_c, dV_c*/dlam) of chamber c at pressure p_c."""
        ch = self.scene.chambers[c]
        value = lam if c == self.controlled else self.fixed[c]
        if value is None:
            raise SnapmemError(f"chamber {c + 1}: its {'volume' if ch.kind is ChamberKind.VOLUME else 'gas amount'} "
                               "is not set; start the trace from a state, or set it")
        if ch.kind is ChamberKind.VOLUME:
            return value, 0.0, 1.0
        gamma = ch.exponent
        v = gas_volume(pressure, value, ch.p_atm, gamma)
        dv_damount = 1.0 / (pressure + ch.p_atm) if gamma == 1.0 else v / (gamma * value)
        return v, -gas_compliance(pressure, value, ch.p_atm, gamma), dv_damount

    def evaluate(self, x, lam, order=2, with_floor=False):
        sc = self.scene
        q, loads = self.state(x, lam)
        ev = sc.evaluate(q, loads, order)
        k = len(self.multiplied)
        G = np.empty((sc.n_free, k))
        rows, D = np.empty(k), np.zeros((k, k))
        for j, c in enumerate(self.multiplied):
            volume, G[:, j] = sc.chamber_volume_and_gradient(q, c)
            p = loads[sc.pressure_name(c)]
            v_star, dv_dp, _ = self.target(c, p, lam)
            rows[j] = -(volume - v_star)
            D[j, j] = -dv_dp
        F = np.concatenate([ev.residual, rows])
        J = None if order < 2 else ChamberJacobian(ev.stiffness, -G, -G, -D)
        return (F, J, ev.residual_floor) if with_floor else (F, J)

    def dF_dlam(self, x, lam):
        sc = self.scene
        j = None if self.load is not None else self.multiplied.index(self.controlled)
        if j is not None and sc.chambers[self.controlled].kind is ChamberKind.VOLUME:
            d = np.zeros(self.n)              # a fluid's volume: dV*/dlam = 1, whatever the state
            d[sc.n_free + j] = 1.0
            return d
        q, loads = self.state(x, lam)
        if self.load is not None:
            return np.concatenate([sc.load_derivative(q, self.load, loads), np.zeros(len(self.multiplied))])
        d = np.zeros(self.n)
        _, _, dv_dlam = self.target(self.controlled, loads[sc.pressure_name(self.controlled)], lam)
        d[sc.n_free + j] = dv_dlam
        return d

    def inadmissible(self, x, lam):
        q, loads = self.state(x, lam)
        why = self.scene.inadmissible(q)
        if why is None:
            for c in self.multiplied:
                ch = self.scene.chambers[c]
                if ch.is_gas and not loads[self.scene.pressure_name(c)] + ch.p_atm > 0:
                    return f"chamber {c + 1}: absolute gas pressure not positive"
                if ch.kind is ChamberKind.ADIABATIC and not self.scene.chamber_volume(q, c) > 0:
                    return f"chamber {c + 1}: the gas volume is not positive"
        return why

    # ----------------------------------------------------------------------------------------
    def factorise(self, J):
        lu = J.factor(J.A.factor())
        return lu, lu

    def stability(self, J, x, lam, n_eigs, start=None, tol=1e-10, sweeps=40, lu=None):
        """(J's n_eigs eigenvalues nearest zero, the total energy's negative count on the chambers'
        constraints (Haynsworth, module docstring), their vectors, the iterated subspace).

        The iteration stops after :data:`ROUNDING_SWEEPS` sweeps if the eigenvalue nearest zero is
        within :data:`ROUNDING_EIGENVALUE` |J| of it (at a BP): J^-1's huge Ritz value carries
        eps / |eigenvalue| into the others, which never settle (all 40 sweeps ran there)."""
        if lu is None:
            lu = J.factor(J.A.factor())
        first = min(sweeps, ROUNDING_SWEEPS)
        eigs, vectors, subspace = eigenvalues_near_zero(J, n_eigs, start, lu, tol, max_iterations=first,
                                                        subspace=True)
        if sweeps > first and not np.min(np.abs(eigs)) <= ROUNDING_EIGENVALUE * scale_of(J):
            eigs, vectors, subspace = eigenvalues_near_zero(J, n_eigs, subspace, lu, tol,
                                                            max_iterations=sweeps - first, subspace=True)
        negative = getattr(lu.inner, "negative", None)
        negative = J.A.negative_count() if negative is None else negative
        k = lu.S.shape[0]
        if k:
            negative += int(np.count_nonzero(np.linalg.eigvalsh(0.5 * (lu.S + lu.S.T)) < 0)) - k
        return eigs, negative, vectors, subspace

    def stiffness(self, J):
        return J

    def arclength_factor(self, J, Fl, row, corner, lu=None):
        """The tracer's arclength system [[J, Fl], [row^T, corner]] factorised as the band K bordered
        once by k + 1 columns and rows ([-G, Fl's and row's state parts], corner [[-D, Fl's
        pressure part], [row's, corner]]): one block elimination refined on the exact product, not
        J's nested in the border's (3 band solves a solve, not 5). ``lu``: J's, whose K is reused."""
        n, k = J.A.n, J.D.shape[0]
        B = np.empty((n, k + 1))
        B[:, :k], B[:, k] = J.B, Fl[:n]
        C = np.empty((n, k + 1))
        C[:, :k], C[:, k] = J.C, row[:n]
        D = np.empty((k + 1, k + 1))
        D[:k, :k], D[:k, k], D[k, :k], D[k, k] = J.D, Fl[n:], row[n:], corner[0][0]
        return BorderedMatrix(J.A, B, C, D).factor(None if lu is None else lu.inner)

    def null_mode_borders(self, x, lam, J) -> list:
        return [self.dF_dlam(x, lam)]

    # ----------------------------------------------------------------------------------------
    def measures(self, x, lam) -> dict:
        sc = self.scene
        q, loads = self.state(x, lam)
        out = {"pressure": loads.get("pressure", 0.0), "voltage": loads.get("voltage_1", 0.0),
               "E_hat": sc.e_hat(loads.get("voltage_1", 0.0))}
        out.update({k: v for k, v in loads.items() if k.startswith("pressure_") or k.startswith("voltage_")})
        out.update(sc.measures(q, loads))
        reduced = sc.reduced(q)
        if reduced is not None:          # identical membranes: the state's evaluation was one membrane's
            out["reduced"] = reduced
        for c, ch in enumerate(sc.chambers):
            if ch.is_gas:
                amount = lam if c == self.controlled else self.fixed[c]
                out["gas_amount" if c == 0 else f"gas_amount_{c + 1}"] = float(amount)
        return out

    def unknowns(self, q, loads) -> tuple:
        """(x, lam) of a full state q under ``loads``; fluid volumes and gas amounts not yet set are
        taken from the state (a fluid's volume V_c(q), a gas' amount (p_c + p_atm) V_c(q)^gamma)."""
        sc = self.scene
        held = {}
        for c in self.multiplied:
            ch = sc.chambers[c]
            v = sc.chamber_volume(q, c)
            held[c] = v if ch.kind is ChamberKind.VOLUME else (loads[sc.pressure_name(c)] + ch.p_atm) * (
                v if ch.exponent == 1.0 else v ** ch.exponent)
            if c != self.controlled and self.fixed[c] is None:
                self.fixed[c] = held[c]
        lam = loads[self.load] if self.load is not None else held[self.controlled]
        return self.x_of(q, loads), float(lam)

    def lam_of(self, loads) -> float:
        if self.load is None:
            raise SnapmemError(f"control {self.control!r}: the parameter is an output; start from a state")
        return loads[self.load]

    def start_loads(self, loads: dict) -> dict:
        return loads

    # ----------------------------------------------------------------------------------------
    def exchange(self) -> np.ndarray | None:
        """The permutation P of the unknowns x that exchanges two identical membranes (x -> x[P]),
        if the problem has that symmetry, else None.

        Symmetric: a scene of two membranes with the same number of free degrees of freedom,
        each bounding the same chambers with the same sign, whose residual and energy commute with
        the exchange: F(P x) = P F(x) to 1e-12 relative at a deformed, unequal state (checked
        numerically, so any difference of law, thickness, radius, voltage or supports breaks it).
        Then the branch through a symmetric state along an antisymmetric direction has as its
        mirror image the branch along the opposite direction (branch switching traces one half).
        """
        if getattr(self, "_exchange", False) is not False:
            return self._exchange
        self._exchange = None
        sc = self.scene
        if len(sc.membranes) != 2 or sc.membranes[0].n_free != sc.membranes[1].n_free:
            return None
        if sc.chamber_of[0] != sc.chamber_of[1] or (self.load or "").startswith("voltage_"):
            return None                       # (a voltage control drives one membrane only)
        if not np.array_equal(sc.membranes[0].reference_state(), sc.membranes[1].reference_state()):
            return None
        m = sc.n_free // 2
        perm = np.concatenate([np.arange(m, 2 * m), np.arange(m), np.arange(2 * m, self.n)])
        x0, lam0 = self.x_of(self._reference), self._probe_parameter()
        wave = np.sin(np.arange(self.n) * 0.7 + 0.3)
        x = x0 + 1e-2 * sc.meridian.size * wave * (np.arange(self.n) < sc.n_free)
        x[sc.n_free:] = 0.01 * self.p_scale
        F, _ = self.evaluate(x, lam0, order=1)
        F_mirror, _ = self.evaluate(x[perm], lam0, order=1)
        if np.max(np.abs(F_mirror - F[perm])) <= 1e-12 * max(np.max(np.abs(F)), 1e-300):
            self._exchange = perm
        return self._exchange

    def _probe_parameter(self) -> float:
        """A value of the parameter to test the exchange at (the reference volume or gas amount)."""
        if self.load is not None:
            return self.base.get(self.load, 0.0)
        ch = self.scene.chambers[self.controlled]
        v = self.scene.chamber_volume(self._reference, self.controlled)
        return v if ch.kind is ChamberKind.VOLUME else ch.p_atm * v ** ch.exponent

    def mirrored_point(self, p, perm: np.ndarray):
        """The exchange image of a point: state, tangent and eigenvectors permuted by ``perm``
        (:meth:`exchange`), the same parameter, eigenvalues and inertia."""
        from dataclasses import replace
        tangent = None if p.tangent is None else np.append(p.tangent[:-1][perm], p.tangent[-1])
        return replace(p, x=p.x[perm], tangent=tangent,
                       vectors=None if p.vectors is None else p.vectors[perm],
                       subspace=None if p.subspace is None else p.subspace[perm], measured=None)


#: Inverse-iteration sweeps after which an eigenvalue nearest zero at rounding ends the iteration
#: (ChamberProblem.stability), and that rounding, relative to |J| (its largest diagonal entry).
ROUNDING_SWEEPS = 8
ROUNDING_EIGENVALUE = 1e3 * float(np.finfo(float).eps)


def _chamber_problem(scene, control):
    """The problem of a multi-membrane scene (None for any other scene)."""
    return ChamberProblem(scene, control) if isinstance(scene, MultiScene) else None


PROBLEM_FACTORIES.append(_chamber_problem)


# ----------------------------------------------------------------------------------------------
# the limit points of a gas chamber's amount as its reservoir's volume varies
def reservoir_at_fold(pb, p, p_atm: float, gamma: float = 1.0) -> float:
    """The reservoir volume V_d [m^3] for which point ``p`` of a branch traced in the pressure of a
    single chamber is a limit point of the gas amount (inf where there is none).

    The membranes feel only the chamber's pressure, so a gas chamber's equilibria are the
    pressure-controlled ones with A = P (V + V_d)^gamma (P = p + p_atm, V the membranes' volume).
    Along the branch dA = 0 where (V + V_d) dp + gamma P dV = 0:

        V_d = -gamma P (dV/ds) / (dp/ds) - V,

    with dp/ds the tangent's parameter part and dV/ds = -dR/dp . dx/ds (the pressure's work is
    -p V). So the branch parametrises the curve of the gas amount's limit points in V_d exactly
    on the mesh (the discrete model's own relation, no approximation)."""
    if p.tangent is None:
        raise SnapmemError("reservoir_at_fold: the point has no tangent")
    dp = float(p.tangent[-1])
    dV = -float(pb.dF_dlam(p.x, p.lam) @ p.tangent[:-1])
    volume = float(pb.point_measures(p)["volume"])
    if dp == 0.0 or not dV * dp < 0.0:
        return float("inf")
    return -gamma * (p.lam + p_atm) * dV / dp - volume


def reservoir_folds(branch, p_atm: float, gamma: float = 1.0, tol: float = 1e-12) -> dict:
    """The curve of the gas amount's limit points in the reservoir volume, from a branch traced in
    the chamber's pressure (``branch.control`` = 'pressure'; :func:`reservoir_at_fold`), and its cusp.

    Parameters
    ----------
    branch : Branch
        Traced in pressure through the falling part of its pressure curve (past its pressure
        maximum and minimum, e.g. the balloon to stretch 3).
    p_atm : float
        Ambient absolute pressure [Pa].
    gamma : float
        1 for an isothermal gas, the adiabatic exponent for an adiabatic one.
    tol : float
        Relative tolerance in arclength of the cusp's location.

    Returns
    -------
    dict
        ``curve``: pandas.DataFrame, one row per branch point with a limit point (s, pressure,
        volume, the scene's measures, ``reservoir`` V_d [m^3], ``amount`` P (V + V_d)^gamma, ``side``
        'max' before the cusp (the amount's maximum: the snap) or 'min' after it (the snap back));
        ``cusp``: the same quantities at the smallest V_d, located by Brent's method on the branch
        between its neighbours (corrector at each trial arclength): below that reservoir the gas
        amount has no limit point, no snap.
    """
    import pandas as pd
    from scipy.optimize import minimize_scalar

    fold = _ReservoirFolds(branch, p_atm, gamma)
    k = fold.smallest
    base, span = fold.states[k - 1], fold.states[k + 1].s - fold.states[k - 1].s
    found = minimize_scalar(lambda s: fold.reservoir(fold.at(base, s)), bounds=(0.0, span),
                            method="bounded", options={"xatol": tol * max(span, 1.0)})
    cusp_point = fold.at(base, float(found.x))
    rows = [fold.row(fold.states[i], "max" if fold.states[i].s < cusp_point.s else "min") for i in fold.finite]
    return {"curve": pd.DataFrame(rows), "cusp": fold.row(cusp_point, "cusp")}


def reservoir_limit_points(branch, reservoir: float, p_atm: float, gamma: float = 1.0, cusp: dict | None = None) -> list:
    """[max, min]: the gas amount's two limit points on a reservoir of ``reservoir`` [m^3] (the
    snap and the snap back), as rows of :func:`reservoir_folds`' curve, located on the pressure
    branch ``branch`` by Brent's method (to 1e-12 in V_d) on either side of the cusp; [] below the
    cusp's reservoir (no snap). ``cusp``: :func:`reservoir_folds`' cusp, if already found."""
    from scipy.optimize import brentq

    cusp = reservoir_folds(branch, p_atm, gamma)["cusp"] if cusp is None else cusp
    if not reservoir > cusp["reservoir"]:
        return []
    fold = _ReservoirFolds(branch, p_atm, gamma)
    s_cusp = cusp["s"]
    out = []
    for side in ("max", "min"):
        # consecutive branch points (or a point and the cusp) with V_d on either side of ``reservoir``
        ends = [(fold.states[i].s, fold.values[i], fold.states[i]) for i in fold.bracketing]
        ends = [e for e in ends if (e[0] < s_cusp) == (side == "max")]
        ends = sorted(ends + [(s_cusp, cusp["reservoir"], None)], key=lambda e: e[0])
        pairs = [(a, b) for a, b in zip(ends[:-1], ends[1:]) if (a[1] > reservoir) != (b[1] > reservoir)]
        if not pairs:
            raise SnapmemError(f"reservoir_limit_points: reservoir = {reservoir:g} is beyond the branch's {side} "
                               "side (trace the pressure branch closer to its extrema)")
        (s_a, _, point_a), (s_b, _, _) = pairs[0]
        base = point_a if point_a is not None else max((fold.states[i] for i in fold.bracketing
                                                        if fold.states[i].s <= s_a), key=lambda p: p.s)
        s = brentq(lambda t: min(fold.reservoir(fold.at(base, t)), _FAR) - reservoir, s_a - base.s, s_b - base.s,
                   xtol=1e-12 * max(s_b - s_a, 1e-300))
        out.append(fold.row(fold.at(base, s), side))
    return out


#: V_d [m^3] standing for "no finite reservoir" (at and beyond the pressure extrema) in root brackets.
_FAR = 1e300


class _ReservoirFolds:
    """The pressure branch's points and :func:`reservoir_at_fold` along it, with the corrector to
    reach any arclength between them."""

    def __init__(self, branch, p_atm: float, gamma: float):
        from snapmem.continuation.options import ContinuationOptions
        from snapmem.continuation.problems import make_problem
        from snapmem.continuation.tracer import Tracer

        if branch.control != "pressure":
            raise SnapmemError(f"reservoir folds: the branch is traced in {branch.control!r}; trace it in 'pressure'")
        self.p_atm, self.gamma = p_atm, gamma
        self.pb = make_problem(branch.scene, "pressure")
        self.states = [p for p in branch.states if p.tangent is not None]
        self.values = np.array([self.reservoir(p) for p in self.states])
        self.finite = [int(i) for i in np.flatnonzero(np.isfinite(self.values))]
        if len(self.finite) < 3:
            raise SnapmemError("reservoir folds: the branch has no falling part of its pressure curve "
                               "(trace it past the pressure maximum)")
        # the falling part with its neighbours (the pressure extrema, where V_d -> inf) as bracket ends
        first, last = max(self.finite[0] - 1, 0), min(self.finite[-1] + 1, len(self.states) - 1)
        self.bracketing = list(range(first, last + 1))
        self.values = np.minimum(self.values, _FAR)
        self.smallest = min(self.finite, key=lambda i: self.values[i])
        if self.smallest in (self.finite[0], self.finite[-1]):
            raise SnapmemError("reservoir folds: the smallest reservoir is at an end of the falling part; trace further")
        self.tracer = Tracer(self.pb, ContinuationOptions(), branch.scene)

    def reservoir(self, p) -> float:
        return reservoir_at_fold(self.pb, p, self.p_atm, self.gamma)

    def at(self, base, s):
        """The branch's point at arclength s past ``base``, with its tangent."""
        point, _ = self.tracer.point_at(base, s, tangent=True, precise=False, stability=False)
        return point

    def row(self, p, side: str) -> dict:
        reservoir = self.reservoir(p)
        m = self.pb.point_measures(p)
        return {"s": p.s, "pressure": p.lam, **{k: v for k, v in m.items() if k != "pressure"},
                "reservoir": reservoir, "amount": (p.lam + self.p_atm) * (m["volume"] + reservoir) ** self.gamma,
                "side": side}
