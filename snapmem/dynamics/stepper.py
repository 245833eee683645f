"""One implicit time step on a scene (:class:`_Stepper`) and the frames a run records (:class:`_Recorder`).

A time step is a Newton solve of the incremental potential

    Pi(y, t*) + (1/2)(y - q_n - h v_n)^T M (y - q_n - h v_n) / h^2 + (1/2)(y - q_n)^T C (y - q_n) / h

(C = xi M the mass-proportional damping), i.e. backward Euler with step h: the scene's gradient
and banded (or bordered) stiffness plus the diagonal M / h^2 + C / h. Every energy term, contact
barriers included, enters unchanged, and Newton's ``max_step`` keeps each iterate short of any
contact gap, so no accepted state penetrates a body. The schemes (:mod:`snapmem.dynamics.schemes`)
choose its anchor (q_n, v_n), step h and load time t*.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping

import numpy as np

from snapmem.dynamics.compiled_assembly import NetworkStep
from snapmem.dynamics.compiled_step import CompiledStep
from snapmem.dynamics.options import DynamicsOptions
from snapmem.dynamics.trajectory import Trajectory
from snapmem.errors import SnapmemError
from snapmem.kernels import viscous as _viscous_kernels
from snapmem.kernels.switch import compiled
from snapmem.model.contact import contact_report, contact_terms
from snapmem.model.local_checks import failure_margins_many
from snapmem.model.scene import Evaluation, Scene
from snapmem.model.viscous import viscous_terms
from snapmem.solvers.newton import newton

EPS = float(np.finfo(float).eps)


class _Stepper:
    """One implicit step (backward Euler solve of the incremental potential) on a scene."""

    def __init__(self, scene: Scene, mass: np.ndarray, damping: np.ndarray, options: DynamicsOptions):
        self.scene, self.mass, self.damping, self.options = scene, mass, damping, options
        self.free = scene.free
        self.tol = options.newton.tol * scene.force_scale
        self._mass_free, self._damping_free = mass[self.free], damping[self.free]
        self._size = scene.meridian.size
        # Newton's increment test: its error within newton_fraction of the smallest error tolerance
        # a step can have (tol times the reference size; the driver's is tol max(L, max |q|))
        self.increment_tol = options.newton_fraction * options.tol * self._size if options.adaptive else 0.0
        # the whole Newton solve in one compiled call where the scene's terms allow it
        self.compiled = CompiledStep.of(scene) if options.line_search == "energy" else None

    def solve(self, q, v, h, loads, current=None, outcome=None):
        """y minimising the incremental potential of step h from (q, v); (y, report).

        Newton starts from the predictor q + h v if it is admissible, else from ``current`` (the
        present state, always admissible; default q). ``outcome``: (kind, step, a_previous) of the
        scheme's outcome of the step, which the compiled solve computes in the same call
        (:meth:`outcome` hands it out)."""
        if self.compiled is not None:
            done = self.compiled.solve(q, v, h, loads, q if current is None else current, self._mass_free,
                                       self._damping_free, self.tol, self._size, self.options.newton, outcome,
                                       self.increment_tol)
            if done is not None:
                return done
        scene, free = self.scene, self.free
        inertia_free = self._mass_free / h ** 2 + self._damping_free / h
        momentum = self._mass_free * v[free] / h

        def assemble(y):
            ev = scene.evaluate(y, loads, order=2)
            d = (y - q)[free]
            residual = ev.residual + inertia_free * d - momentum
            energy = ev.energy + 0.5 * float(d @ (inertia_free * d)) - float(momentum @ d)   # + const
            K = ev.stiffness
            K.add_diagonal(inertia_free)
            return Evaluation(energy, ev.gradient, residual, K, ev.residual_floor)

        guess = q + h * v
        # the inertia term's rounding floor, eps |q| M / h^2, grows as h falls: keep the tolerance above it
        tol = max(self.tol, 1e3 * EPS * float(inertia_free.max()) * self._size)
        if scene.inadmissible(guess) is not None:
            guess = q if current is None else current
        solver = functools.partial(newton, merit=self.options.line_search, increment_tol=self.increment_tol,
                                   mass=self._mass_free)
        y, _ev, report = solver(assemble, guess, free, tol, self.options.newton, scene.inadmissible, scene.max_step)
        return y, report

    def outcome(self, anchor, y, a_prev, free, n_node_dofs) -> tuple:
        """The step's outcome from the solve's y (``Scheme.outcome``, which documents it): the
        compiled solve's, if it computed it for this very y, else the scheme's own."""
        done = getattr(self.compiled, "outcome", None)         # (a chambers' compiled step computes none)
        if done is not None and done[0] is y:
            _, q_new, v_new, a_new, change, largest = done
            return q_new, v_new, a_new, anchor.scheme.estimate(anchor.dt, change), float(largest)
        return anchor.scheme.outcome(anchor, y, a_prev, free, n_node_dofs)


def scheme_coefficients(scheme, t: float, dt: float, past_dt: float | None) -> tuple:
    """The linear maps of a scheme's step on a state at rest (the viscous networks' internal
    stretches have no velocity): ``scheme.rest_coefficients`` (t, the step's start [s], does not
    enter: a scheme's anchor uses it for its load time only).

    Returns (h, c_now, c_previous, n_star, n_now, n_previous): the step of the incremental
    potential [s], the anchor x_hat = c_now x_n + c_previous x_{n-1} and the new state
    x_{n+1} = n_star y + n_now x_n + n_previous x_{n-1} from the solve's y; ``past_dt`` the last
    step [s] (None: no history, the c_previous and n_previous are 0).
    """
    return scheme.rest_coefficients(dt, past_dt)


class _InternalState:
    """The internal stretches of the scene's viscous networks (:mod:`snapmem.model.viscous`) across steps.

    They follow the step's scheme exactly as the positions do: the scheme's anchor of the state
    zeta (its x_hat, with the same h) opens the networks' incremental potential before the solve,
    and the scheme's ``new_state`` turns the solve's zeta*(y) into zeta_{n+1} (the midpoint rule:
    2 zeta* - zeta_n). The networks start relaxed at the initial state q0 (xi = lam there: the
    reference state gives xi = 1). Without viscous terms every method does nothing.

    Every scheme is linear in the states, so a step's anchor is c_now zeta_n + c_previous
    zeta_{n-1} and its new state n_star zeta* + n_now zeta_n + n_previous zeta_{n-1}:
    :func:`scheme_coefficients` reads those numbers off the scheme itself (its formulas stay in
    snapmem.dynamics.schemes), and one compiled call per step and term applies them
    (snapmem.kernels.viscous ``anchor_internal``, ``update_internal``, which adds the step's
    dissipation) into arrays kept for the run: no per-step arrays, no per-step Python on them.
    Where the scene's compiled step (``compiled``) covers its one term, that step's own call does
    both (``CompiledStep.take_network_step``): a step is one compiled call.
    """

    def __init__(self, scene: Scene, q0: np.ndarray, compiled: CompiledStep | None = None):
        self.scene, self.terms = scene, viscous_terms(scene)
        kin = scene.kinematics(q0)
        relaxed = np.log(np.stack([kin.lam1, kin.lam2]))
        # during the run, an evaluation outside a solve (the first acceleration, the frames'
        # energies) sees the networks' stored energy at their present internal stretches
        self._limits = [term.limit for term in self.terms]
        for term in self.terms:          # the networks start relaxed at q0 (xi = lam: at rest there long)
            term.reset(np.repeat(relaxed[None], term.networks, axis=0))
            term.limit = "instantaneous"
        self.previous = None               # zeta_{n-1} of every term (the scheme's history)
        self.dissipated = 0.0              # [J] since the start
        # the run's arrays of every term: the open step's anchor, the pending new state, a spare
        self._hats = [np.empty_like(term.zeta) for term in self.terms]
        self._news = [np.empty_like(term.zeta) for term in self.terms]
        self._coefficients = None          # (h, c_now, c_previous, n_star, n_now, n_previous) of the open step
        self._pending = None               # the pending step's dissipation [J] of every term
        # the kernels of the run (compiled, or their Python on the reference path)
        self._anchor, self._update = self._kernel("anchor_internal"), self._kernel("update_internal")
        # the compiled step that opens and closes the one term's steps itself, or None
        self._fused = compiled if (compiled is not None and len(self.terms) == 1
                                   and compiled.viscous_term is self.terms[0]) else None
        self._step_coefficients = np.zeros(7)      # (h, c_now, c_previous, n_star, n_now, n_previous, dt)
        self._dissipated = np.zeros(1)             # the fused step's dissipation [J]
        self._frame = _NetworksFrame(self)         # what frame() hands out (it reads the state when read)

    @staticmethod
    def _kernel(name: str):
        kernel = getattr(_viscous_kernels, name)
        return kernel if compiled() else kernel.py_func

    def open(self, scheme, t: float, dt: float, history) -> None:
        """Before a solve: the anchor of every term's incremental potential for ``scheme``'s step."""
        if not self.terms:
            return
        past_dt = None if history is None or self.previous is None else history[2]
        self._coefficients = coefficients = scheme_coefficients(scheme, t, dt, past_dt)
        h, c_now, c_previous = coefficients[:3]
        if self._fused is not None:            # the compiled step's call opens (and closes) it
            term, hat, values = self.terms[0], self._hats[0], self._step_coefficients
            values[:6] = coefficients
            values[6] = dt
            previous = term.zeta if self.previous is None else self.previous[0]
            self._fused.take_network_step(NetworkStep(term.zeta, previous, values, term.viscosities, self._news[0],
                                                      self._dissipated))
            term.begin_step(h, hat)
            return
        for i, (term, hat) in enumerate(zip(self.terms, self._hats)):
            previous = term.zeta if self.previous is None else self.previous[i]
            self._anchor(term.zeta, previous, c_now, c_previous, hat)
            term.begin_step(h, hat)

    def close(self, y: np.ndarray | None, dt: float) -> None:
        """After a solve: the step's new internal state at y (None: the solve failed), kept pending."""
        if not self.terms:
            return
        pending = None
        if y is not None and self._fused is not None and self._fused.network_step_closed_at is y:
            pending = [float(self._dissipated[0])]            # the compiled step wrote the new state
        elif y is not None:
            h, _, _, n_star, n_now, n_previous = self._coefficients
            update, weight, pending = self._update, self.scene.weight, []
            for i, (term, hat, new) in enumerate(zip(self.terms, self._hats, self._news)):
                star = term.internal_at(y, self.scene)        # the compiled solve's own, if it took the step
                previous = term.zeta if self.previous is None else self.previous[i]
                pending.append(float(update(star, term.zeta, previous, n_star, n_now, n_previous, hat, h, dt,
                                            term.viscosities, weight, new)))
        for term in self.terms:
            term.end_step()
        self._pending = pending

    def commit(self) -> None:
        """The step was accepted: its pending internal state becomes the state (the arrays rotate:
        the state becomes the history, the history's array takes the next step's new state)."""
        if not self.terms or self._pending is None:
            return
        spares = self._news if self.previous is None else self.previous
        self.previous = [term.zeta for term in self.terms]
        for term, new, dissipated in zip(self.terms, self._news, self._pending):
            term.commit(new)
            self.dissipated += dissipated
        self._news = [np.empty_like(new) if spare is new else spare for spare, new in zip(spares, self._news)]
        self._pending = None

    def finish(self) -> None:
        """The run is over: the terms back to their static limits (their last state kept)."""
        for term, limit in zip(self.terms, self._limits):
            term.end_step()
            term.limit = limit

    def state(self) -> dict:
        """What a continued run needs of the networks (:meth:`restore`): ``zeta`` and ``zeta_previous``
        (K, 2, E) of every term (the scheme's history), ``dissipated`` [J]; empty without networks."""
        if not self.terms:
            return {}
        return {"zeta": [term.zeta for term in self.terms], "dissipated": self.dissipated,
                "zeta_previous": None if self.previous is None else list(self.previous)}

    def restore(self, saved: dict) -> None:
        """Continue from :meth:`state` of an earlier run (nothing to do without networks)."""
        if not self.terms:
            return
        if "zeta" not in saved or len(saved["zeta"]) != len(self.terms):
            raise SnapmemError("restart: the saved run has no internal stretches for this scene's viscous networks "
                               "(was it run with the same viscous_mu?)")
        for term, zeta in zip(self.terms, saved["zeta"]):
            zeta = np.array(zeta, dtype=float)
            if zeta.shape != term.zeta.shape:
                raise SnapmemError(f"restart: saved internal stretches of shape {zeta.shape}, this scene's networks "
                                   f"have {term.zeta.shape} (same nodes and viscous_mu?)")
            term.reset(zeta)
        previous = saved.get("zeta_previous")
        self.previous = None if previous is None else [np.array(z, dtype=float) for z in previous]
        self.dissipated = float(saved.get("dissipated", 0.0))

    def adopt(self, zeta: np.ndarray, previous: np.ndarray | None, dissipated: float) -> None:
        """Take the state a compiled run (snapmem.dynamics.compiled_run) advanced the one term to: its
        internal log stretches ``zeta`` and last ones ``previous`` (K, 2, E; None: no history),
        the dissipation [J] since the start (the arrays are copied: the run keeps writing its own)."""
        term = self.terms[0]
        term.commit(zeta.copy())
        self.previous = None if previous is None else [previous.copy()]
        self.dissipated = float(dissipated)
        self._news, self._pending = [np.empty_like(zeta)], None

    def set_frame(self, zeta: np.ndarray) -> None:
        """Put a frame's internal log stretches ``zeta`` (K, 2, E) back into the terms (to measure it)."""
        start = 0
        for term in self.terms:
            term.zeta = zeta[start: start + term.networks]
            start += term.networks

    def stored_energies(self, Q: np.ndarray, zetas: np.ndarray) -> np.ndarray:
        """The networks' stored energy [J] of every frame (T,): states Q (T, n), the frames' internal
        log stretches ``zetas`` (T, K, 2, E) (all terms' networks stacked), in one call per term."""
        m, kernel = self.scene.meridian, self._kernel("stored_energy_frames")
        Q = np.ascontiguousarray(Q, dtype=float)
        energy, start = np.zeros(len(Q)), 0
        for term in self.terms:
            part = np.ascontiguousarray(zetas[:, start: start + term.networks])
            energy = energy + kernel(Q, m.edges, m.inverse_length, m.inverse_mid_radius, part, term.moduli,
                                     term.jlims, self.scene.weight)
            start += term.networks
        return energy

    def frame(self):
        """What a frame records, read when the recorder keeps a frame (not every step): ``zeta``
        (K, 2, E) the internal log stretches of every network (all terms' networks stacked; the
        trajectory has ``xi`` = exp(zeta)), ``dissipation`` [J] dissipated by the dashpots since the
        start. An empty mapping without networks. The same object at every step: it reads the
        state when the recorder reads it."""
        return self._frame if self.terms else {}


class _Block:
    """Frames the compiled run recorded (:meth:`_Recorder.add_frames`): ``columns`` by key, each with
    a leading frame axis, and every frame's ``loads``; :meth:`pop` drops the last frame."""

    __slots__ = ("columns", "loads", "t")

    def __init__(self, columns: dict, loads: list):
        self.columns, self.loads, self.t = columns, loads, columns["t"]

    def pop(self) -> None:
        self.t = self.t[:-1]


class _NetworksFrame(Mapping):
    """The networks' part of a frame (:meth:`_InternalState.frame`), read from the state when the
    recorder keeps the frame: the driver asks for one every step, the recorder reads few."""

    __slots__ = ("_state",)
    KEYS = ("zeta", "dissipation")

    def __init__(self, state: _InternalState):
        self._state = state

    def __iter__(self):
        return iter(self.KEYS)

    def keys(self):                    # what {**frame} asks for: the names, without a view
        return self.KEYS

    def __len__(self) -> int:
        return len(self.KEYS)

    def __getitem__(self, key):
        if key == "zeta":
            return self._zeta()
        if key == "dissipation":
            return self._state.dissipated
        raise KeyError(key)

    def _zeta(self) -> np.ndarray:
        terms = self._state.terms                        # a copy: the arrays rotate
        return terms[0].zeta.copy() if len(terms) == 1 else np.concatenate([term.zeta for term in terms])

    def read(self) -> dict:
        """The frame's values now, as a dict (what the recorder keeps of a frame)."""
        return {"zeta": self._zeta(), "dissipation": self._state.dissipated}


class _Recorder:
    """Collects frames: the state every frame, the smallest contact gap every step; the frames'
    energies, volumes and contact reports when the trajectory is built.

    With the scene's compiled step (``compiled``) those come from one compiled call over all
    frames (``CompiledStep.measures_many``) instead of three assemblies per frame.
    """

    def __init__(self, scene: Scene, mass, interval: float, compiled: CompiledStep | None = None,
                 internal: _InternalState | None = None):
        self.scene, self.mass, self.interval, self.compiled = scene, mass, interval, compiled
        self.internal = internal
        self.contacts = contact_terms(scene)
        self.rows: list[dict] = []
        self.last_t = -np.inf
        self.min_gap = np.inf

    def _gap(self, q):
        if not self.contacts:
            return np.inf
        if self.compiled is not None:
            return self.compiled.min_gap(q)
        x = self.scene.node_coordinates(q)
        gaps = [t.gaps(x, y).min() for t, y in zip(self.scene.node_terms, self.scene.body_coordinates(q))
                if t in self.contacts]
        return min(gaps)

    def record(self, t, q, v, loads, dt, iterations, force=False, internal=None):
        if not force and t - self.last_t < self.interval:
            self.min_gap = min(self.min_gap, self._gap(q))
            return
        rows = self.rows
        if rows and type(rows[-1]) is _Block:
            if rows[-1].t[-1] == t:
                rows[-1].pop()
                if not rows[-1].t.size:
                    rows.pop()
        elif rows and rows[-1]["t"] == t:
            rows.pop()
        kinetic = 0.5 * float(self.mass @ (v * v))
        if type(internal) is _NetworksFrame:        # the networks' values now, read once
            internal = internal.read()
        rows.append({"t": t, "q": q.copy(), "v": v.copy(), "kinetic": kinetic, "dt": dt, "newton": iterations,
                     "min_gap": self.min_gap, "loads": loads, **(internal or {})})    # the frame's own gap joins it when measured
        self.last_t = t
        self.min_gap = np.inf

    def add_frames(self, block: dict, loads: list) -> None:
        """Frames the compiled run recorded (snapmem.dynamics.compiled_run): ``block`` the columns a
        row has (``t``, ``q``, ... with a leading frame axis; ``kinetic`` is computed here, by the
        rows' formula), ``loads`` each frame's resolved loads."""
        mass = self.mass
        block["kinetic"] = np.array([0.5 * float(mass @ (v * v)) for v in block["v"]])
        self.rows.append(_Block(block, loads))

    def _frames(self) -> tuple[dict, list]:
        """Every frame's recorded values as arrays by key (the rows' and the compiled blocks', in
        their order; the same arrays as the rows alone would give) and every frame's loads."""
        keys = [k for k in self.rows[0] if k != "loads"]
        columns, loads = {k: [] for k in keys}, []
        for row in self.rows:
            if type(row) is _Block:
                for k in keys:
                    columns[k].extend(row.columns[k][: row.t.size])
                loads.extend(row.loads[: row.t.size])
            else:
                for k in keys:
                    columns[k].append(row[k])
                loads.append(row["loads"])
        return {k: np.array(values) for k, values in columns.items()}, loads

    def _measures(self, Q, loads, zetas):
        """Potential energy, volume, smallest gap (T,) and contact report columns of the frames Q
        (``zetas``: the networks' internal log stretches of every frame, (T, K, 2, E), or None)."""
        if self.compiled is not None:
            energy, volume, gap, columns = self.compiled.measures_many(Q, loads)
            if zetas is not None:                                    # the networks' stored energy of each frame
                energy = energy + self.internal.stored_energies(Q, zetas)
            return energy, volume, gap, columns
        scene = self.scene
        reports = [contact_report(scene, q) for q in Q]
        columns = {k: np.array([r[k] for r in reports]) for k in (reports[0] if reports else {})}
        if zetas is not None:       # each frame's networks' stored energy
            energies = []
            for q, each, zeta in zip(Q, loads, zetas):
                self.internal.set_frame(zeta)
                energies.append(scene.energy(q, each))
            self.internal.set_frame(zetas[-1].copy())
            return (np.array(energies), np.array([scene.volume(q) for q in Q]), np.array([self._gap(q) for q in Q]),
                    columns)
        return (np.array([scene.energy(q, each) for q, each in zip(Q, loads)]),
                np.array([scene.volume(q) for q in Q]), np.array([self._gap(q) for q in Q]), columns)

    def trajectory(self, meta) -> Trajectory:
        """The frames as arrays; node coordinates and body heights and speeds split off q and v."""
        data, loads = self._frames()
        zetas = data.pop("zeta", None)                        # the networks' internal log stretches
        potential, volume, gap, contacts = self._measures(data["q"], loads, zetas)
        if zetas is not None:
            data["xi"] = np.exp(zetas)
        data.update(volume=volume, potential=potential, total=data["kinetic"] + potential,
                    min_gap=np.minimum(data["min_gap"], gap))
        for name in loads[0]:
            data["load_" + name] = np.array([each[name] for each in loads])
        data.update(contacts)
        data.update(failure_margins_many(self.scene, data["q"], [each.get("voltage", 0.0) for each in loads]))
        n = self.scene.n_node_dofs
        data["r"], data["z"] = data["q"][:, 0:n:2].copy(), data["q"][:, 1:n:2].copy()
        for i, body in enumerate(self.scene.bodies):
            data[f"{body.name}_z"] = data["q"][:, n + i].copy()
            data[f"{body.name}_v"] = data["v"][:, n + i].copy()
        return Trajectory(data, meta)

