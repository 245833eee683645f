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

import numpy as np

from snapmem.dynamics.compiled_step import CompiledStep
from snapmem.dynamics.options import DynamicsOptions
from snapmem.dynamics.trajectory import Trajectory
from snapmem.errors import SnapmemError
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
        # the whole Newton solve in one compiled call where the scene's terms allow it
        self.compiled = CompiledStep.of(scene) if options.line_search == "energy" else None

    def solve(self, q, v, h, loads, current=None):
        """y minimising the incremental potential of step h from (q, v); (y, report).

        Newton starts from the predictor q + h v if it is admissible, else from ``current`` (the
        present state, always admissible; default q)."""
        if self.compiled is not None:
            done = self.compiled.solve(q, v, h, loads, q if current is None else current, self._mass_free,
                                       self._damping_free, self.tol, self._size, self.options.newton)
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
        solver = functools.partial(newton, merit=self.options.line_search)
        y, _ev, report = solver(assemble, guess, free, tol, self.options.newton, scene.inadmissible, scene.max_step)
        return y, report


class _InternalState:
    """The internal stretches of the scene's viscous networks (:mod:`snapmem.model.viscous`) across steps.

    They follow the step's scheme exactly as the positions do: the scheme's anchor of the state
    zeta (its x_hat, with the same h) opens the networks' incremental potential before the solve,
    and the scheme's ``new_state`` turns the solve's zeta*(y) into zeta_{n+1} (the midpoint rule:
    2 zeta* - zeta_n). The networks start relaxed at the initial state q0 (xi = lam there: the
    reference state gives xi = 1). Without viscous terms every method does nothing.
    """

    def __init__(self, scene: Scene, q0: np.ndarray):
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
        self._anchors = self._pending = None

    def open(self, scheme, t: float, dt: float, history) -> None:
        """Before a solve: the anchor of every term's incremental potential for ``scheme``'s step."""
        if not self.terms:
            return
        self._anchors = []
        for i, term in enumerate(self.terms):
            z = term.zeta.ravel()
            past = None if history is None or self.previous is None else (
                self.previous[i].ravel(), np.zeros_like(z), history[2])
            anchor = scheme.anchor(z, np.zeros_like(z), t, dt, past)
            term.begin_step(anchor.h, anchor.q.reshape(term.zeta.shape))
            self._anchors.append(anchor)

    def close(self, y: np.ndarray | None, dt: float) -> None:
        """After a solve: the step's new internal state at y (None: the solve failed), kept pending."""
        if not self.terms:
            return
        pending = []
        if y is not None:
            for term, anchor in zip(self.terms, self._anchors):
                star = term.internal_at(y, self.scene)        # the compiled solve's own, if it took the step
                new = anchor.new_state(star.ravel())[0].reshape(star.shape)
                pending.append((new, term.step_dissipation(star, dt, self.scene.weight)))
        for term in self.terms:
            term.end_step()
        self._pending = pending or None

    def commit(self) -> None:
        """The step was accepted: its pending internal state becomes the state."""
        if not self.terms or self._pending is None:
            return
        self.previous = [term.zeta for term in self.terms]
        for term, (new, dissipated) in zip(self.terms, self._pending):
            term.commit(new)
            self.dissipated += dissipated
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

    def set_frame(self, xi: np.ndarray) -> None:
        """Put a frame's internal stretches ``xi`` (K, 2, E) back into the terms (to measure it)."""
        start = 0
        for term in self.terms:
            term.zeta = np.log(xi[start: start + term.networks])
            start += term.networks

    def frame(self) -> dict:
        """What a frame records: ``xi`` (K, 2, E) the internal stretches of every network (all terms'
        networks stacked), ``dissipation`` [J] dissipated by the dashpots since the start."""
        if not self.terms:
            return {}
        return {"xi": np.exp(np.concatenate([term.zeta for term in self.terms])), "dissipation": self.dissipated}


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
        if self.rows and self.rows[-1]["t"] == t:
            self.rows.pop()
        kinetic = 0.5 * float(self.mass @ (v * v))
        self.rows.append({"t": t, "q": q.copy(), "v": v.copy(), "kinetic": kinetic, "dt": dt, "newton": iterations,
                          "min_gap": self.min_gap, "loads": loads, **(internal or {})})    # the frame's own gap joins it when measured
        self.last_t = t
        self.min_gap = np.inf

    def _measures(self, Q, loads):
        """Potential energy, volume, smallest gap (T,) and contact report columns of the frames Q."""
        if self.compiled is not None:
            viscous = self.internal is not None and self.internal.terms
            return self.compiled.measures_many(Q, loads, [row["xi"] for row in self.rows] if viscous else None)
        scene = self.scene
        reports = [contact_report(scene, q) for q in Q]
        columns = {k: np.array([r[k] for r in reports]) for k in (reports[0] if reports else {})}
        if self.internal is not None and self.internal.terms:       # each frame's networks' stored energy
            energies = []
            for q, each, row in zip(Q, loads, self.rows):
                self.internal.set_frame(row["xi"])
                energies.append(scene.energy(q, each))
            self.internal.set_frame(self.rows[-1]["xi"])
            return (np.array(energies), np.array([scene.volume(q) for q in Q]), np.array([self._gap(q) for q in Q]),
                    columns)
        return (np.array([scene.energy(q, each) for q, each in zip(Q, loads)]),
                np.array([scene.volume(q) for q in Q]), np.array([self._gap(q) for q in Q]), columns)

    def trajectory(self, meta) -> Trajectory:
        """The frames as arrays; node coordinates and body heights and speeds split off q and v."""
        loads = [row["loads"] for row in self.rows]
        data = {k: np.array([row[k] for row in self.rows]) for k in self.rows[0] if k != "loads"}
        potential, volume, gap, contacts = self._measures(data["q"], loads)
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

