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
from snapmem.model.contact import contact_report, contact_terms
from snapmem.model.local_checks import failure_margins_many
from snapmem.model.scene import Evaluation, Scene
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


class _Recorder:
    """Collects frames: the state every frame, the smallest contact gap every step; the frames'
    energies, volumes and contact reports when the trajectory is built.

    With the scene's compiled step (``compiled``) those come from one compiled call over all
    frames (``CompiledStep.measures_many``) instead of three assemblies per frame.
    """

    def __init__(self, scene: Scene, mass, interval: float, compiled: CompiledStep | None = None):
        self.scene, self.mass, self.interval, self.compiled = scene, mass, interval, compiled
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

    def record(self, t, q, v, loads, dt, iterations, force=False):
        if not force and t - self.last_t < self.interval:
            self.min_gap = min(self.min_gap, self._gap(q))
            return
        if self.rows and self.rows[-1]["t"] == t:
            self.rows.pop()
        kinetic = 0.5 * float(self.mass @ (v * v))
        self.rows.append({"t": t, "q": q.copy(), "v": v.copy(), "kinetic": kinetic, "dt": dt, "newton": iterations,
                          "min_gap": self.min_gap, "loads": loads})    # the frame's own gap joins it when measured
        self.last_t = t
        self.min_gap = np.inf

    def _measures(self, Q, loads):
        """Potential energy, volume, smallest gap (T,) and contact report columns of the frames Q."""
        if self.compiled is not None:
            return self.compiled.measures_many(Q, loads)
        scene = self.scene
        reports = [contact_report(scene, q) for q in Q]
        columns = {k: np.array([r[k] for r in reports]) for k in (reports[0] if reports else {})}
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

