"""Several membranes in one scene, coupled only through the chambers they bound.

A :class:`MultiScene` holds membranes (each a :class:`~snapmem.model.scene.Scene` with its own
meridian, law, thickness, voltage and supports) and :class:`~snapmem.model.chambers.Chamber` s.
Its state is the membranes' states one after the other, q = (q_1, q_2, ...), and its total
potential the sum of theirs, each under the pressure of its chamber. The stiffness is therefore
block diagonal: the membranes' band matrices stacked into one band matrix (no entry couples two
membranes), so every solve stays O(N) per membrane. A chamber whose pressure is an unknown (a
fluid or a gas) couples its membranes through one border row and column, the gradient of its
volume: :mod:`snapmem.continuation.chambers` borders the band matrix with them.

The scene's loads are each chamber's pressure (``pressure`` for the first, ``pressure_2``, ...
for the others) and each membrane's voltage (``voltage_1``, ``voltage_2``, ... for the membranes
built with a voltage term). Per-membrane measures carry the membrane's number as a suffix
(``volume_1``, ``stretch_2``, ``u_max_1``); ``volume`` is the first chamber's total.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from snapmem.errors import SnapmemError, check_real
from snapmem.kernels.assembly import volume_gradient
from snapmem.kernels.banded import BandedMatrix
from snapmem.kernels.switch import compiled
from snapmem.model.chambers import Chamber
from snapmem.model.scene import Evaluation, Scene
from snapmem.model.terms import PressureWork


class MeridianSet:
    """The reference meridians of a multi-membrane scene, seen as one: ``size`` (the largest
    membrane's, the length scale of tolerances and arclengths), ``nodes`` (all of them), ``q``.
    Not one meridian (``closed`` is None): nothing that needs one curve applies to it."""

    closed = None

    def __init__(self, meridians):
        self.meridians = tuple(meridians)
        self.size = max(m.size for m in self.meridians)
        self.nodes = sum(m.nodes for m in self.meridians)
        self.q = np.concatenate([m.q for m in self.meridians])
        self.r = self.z = np.array([1.0])          # not a sphere (see snapmem.continuation.modes)


class MultiScene:
    """Several membranes and the chambers they bound.

    Parameters
    ----------
    membranes : sequence of Scene
        Each with a pressure-work term if it bounds a chamber, and no rigid bodies.
    chambers : sequence of Chamber
        Each membrane bounds at most one chamber.
    name : str
    parameters : mapping, optional
        Recorded beside results.
    continuation_defaults : mapping, optional
        Continuation options this scene takes where the caller leaves them unset (None), e.g.
        ``{"target_iterations": 5}`` (:func:`snapmem.continuation.options.resolved_target_iterations`);
        an option the caller sets overrides it.
    """

    start_guess = None

    def __init__(self, membranes: Sequence[Scene], chambers: Sequence[Chamber], name: str = "multi",
                 parameters: Mapping | None = None, continuation_defaults: Mapping | None = None):
        self.membranes = tuple(membranes)
        self.continuation_defaults = dict(continuation_defaults or {})
        self.chambers = tuple(chambers)
        if not self.membranes:
            raise SnapmemError("membranes: a multi-membrane scene needs at least one membrane")
        self.name, self.parameters = name, dict(parameters or {})
        self.chamber_of = [None] * len(self.membranes)
        for c, chamber in enumerate(self.chambers):
            for i, s in zip(chamber.membranes, chamber.signs):
                if i >= len(self.membranes):
                    raise SnapmemError(f"chamber {c + 1}: membrane {i} does not exist "
                                       f"(the scene has {len(self.membranes)})")
                if self.chamber_of[i] is not None:
                    raise SnapmemError(f"membrane {i + 1} bounds two chambers; it may bound one")
                if "pressure" not in self.membranes[i].loads:
                    raise SnapmemError(f"membrane {i + 1} bounds chamber {c + 1} but has no pressure work")
                self.chamber_of[i] = (c, s)
        for i, m in enumerate(self.membranes):
            if m.bodies:
                raise SnapmemError(f"membrane {i + 1} has rigid bodies: not supported in a multi-membrane scene")
        sizes = [m.reference_state().size for m in self.membranes]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        self._slices = [slice(int(a), int(b)) for a, b in zip(self.offsets[:-1], self.offsets[1:])]
        self.free = np.concatenate([m.free + o for m, o in zip(self.membranes, self.offsets)])
        self.free_offsets = np.concatenate([[0], np.cumsum([m.n_free for m in self.membranes])]).astype(int)
        self.bandwidth = max(m.bandwidth for m in self.membranes)
        self.meridian = MeridianSet([m.meridian for m in self.membranes])
        # membranes whose pressure work is the swept volume's alone (the chamber's fast path)
        self._swept = [compiled() and [type(t) for t in m.edge_terms + m.density_terms if "pressure" in t.loads]
                       == [PressureWork] for m in self.membranes]
        self._twins = None                 # membrane i -> an earlier identical one (twin_of), found when first asked
        #: False: evaluate every membrane, identical or not (to check the reduction against).
        self.reuse_identical = True
        #: Membrane evaluations (and volumes, domain checks, measures) taken from an identical
        #: membrane in the same state instead of being computed (:meth:`same_as`).
        self.reduced_evaluations = 0
        self.loads = {}
        for c, chamber in enumerate(self.chambers):
            self.loads[self.pressure_name(c)] = float(chamber.pressure)
        for i, m in enumerate(self.membranes):
            if "voltage" in m.loads:
                self.loads[f"voltage_{i + 1}"] = float(m.loads["voltage"])

    # ----------------------------------------------------------------------------------------
    @staticmethod
    def pressure_name(c: int) -> str:
        """The load name of chamber c's pressure: ``pressure``, ``pressure_2``, ..."""
        return "pressure" if c == 0 else f"pressure_{c + 1}"

    @property
    def terms(self) -> tuple:
        """Every membrane's energy terms, membrane by membrane."""
        return tuple(t for m in self.membranes for t in m.terms)

    @property
    def probes(self) -> dict:
        """Every membrane's probes, named with the membrane's number (``stretch_1``): name -> q -> value."""
        return {f"{name}_{i + 1}": (lambda f, i: lambda q: f(self.split(q)[i]))(probe, i)
                for i, m in enumerate(self.membranes) for name, probe in m.probes.items()}

    @property
    def n_free(self) -> int:
        return int(self.free.size)

    @property
    def mu(self) -> float:
        """The first membrane's shear modulus [Pa] (normalises pressures)."""
        return self.membranes[0].mu

    @property
    def thickness(self) -> float:
        return self.membranes[0].thickness

    @property
    def permittivity(self):
        return self.membranes[0].permittivity

    def e_hat(self, voltage: float) -> float:
        return self.membranes[0].e_hat(voltage)

    @property
    def force_scale(self) -> float:
        return max(m.force_scale for m in self.membranes)

    def reference_state(self) -> np.ndarray:
        return np.concatenate([m.reference_state() for m in self.membranes])

    # what the time stepper asks of a scene (snapmem.dynamics): the membranes' dofs, stacked
    bodies = ()

    @property
    def n_node_dofs(self) -> int:
        """All degrees of freedom (the membranes carry no rigid bodies)."""
        return int(self.offsets[-1])

    @property
    def fixed(self) -> tuple:
        """Every membrane's fixed degrees of freedom, in the stacked numbering."""
        return tuple(int(d + o) for m, o in zip(self.membranes, self.offsets) for d in m.fixed)

    def membrane_of_dof(self, i: int) -> int:
        """The membrane (from 0) degree of freedom i of the stacked state belongs to."""
        return int(np.searchsorted(self.offsets, i, side="right") - 1)

    def split(self, q: np.ndarray) -> list:
        """The membranes' states (views of q)."""
        return [q[s] for s in self._slices]

    def supply_load_names(self) -> tuple:
        """The loads a time schedule may add to a scene's (:mod:`snapmem.dynamics.supplies`), per
        chamber with a multiplier: ``fluid_volume`` [m^3] (a fluid chamber's prescribed volume),
        ``source_pressure`` [Pa] and ``flow_resistance`` [Pa s/m^3] (a fluid chamber fed through a
        resistance), ``gas_amount`` [J] (n R T of a gas chamber); suffixed ``_2``, ... beyond the first."""
        names = []
        for c, chamber in enumerate(self.chambers):
            suffix = "" if c == 0 else f"_{c + 1}"
            if chamber.kind.value == "volume":
                names += [f"fluid_volume{suffix}", f"source_pressure{suffix}", f"flow_resistance{suffix}"]
            elif chamber.kind.value == "gas":
                names.append(f"gas_amount{suffix}")
        return tuple(names)

    def resolve_loads(self, loads: Mapping[str, float] | None) -> dict:
        out = dict(self.loads)
        supplies = self.supply_load_names() if loads else ()
        for key, value in (loads or {}).items():
            if key not in out and key in supplies:
                out[key] = check_real(key, value)
                continue
            if key not in out:
                raise SnapmemError(f"load {key!r}: this scene has no such load; it has {sorted(out) or 'none'}")
            out[key] = check_real(key, value)
        return out

    def membrane_loads(self, i: int, loads: Mapping[str, float]) -> dict:
        """The loads of membrane i (its own names: ``pressure``, ``voltage``) from the scene's."""
        own = {}
        if self.chamber_of[i] is not None:
            c, s = self.chamber_of[i]
            own["pressure"] = s * loads[self.pressure_name(c)]
        if f"voltage_{i + 1}" in loads:
            own["voltage"] = loads[f"voltage_{i + 1}"]
        return own

    # ----------------------------------------------------------------------------------------
    # identical membranes: a membrane in the same state as an identical one is not evaluated twice
    def twin_of(self) -> tuple:
        """For each membrane, an earlier membrane identical to it (its index), or None.

        Identical: the same reference state, free and fixed degrees of freedom, chamber and side,
        energy terms (types and reprs) and loads of its own, and bitwise the same energy, residual,
        stiffness and measures at a deformed probe state. Such a membrane in the same state as its
        twin (bitwise, under the same loads) has the same evaluation: the scene takes its twin's
        (:meth:`same_as`), which is how the symmetric states of two identical balloons cost one
        balloon's evaluation, with the same numbers to the last bit. Found at the first call and
        kept: a membrane changed in place afterwards needs ``_twins = None`` again."""
        if not self.reuse_identical:
            return (None,) * len(self.membranes)
        if self._twins is None:
            self._twins = tuple(next((j for j in range(i) if self._identical(j, i)), None)
                                for i in range(len(self.membranes)))
        return self._twins

    def _identical(self, j: int, i: int) -> bool:
        a, b = self.membranes[j], self.membranes[i]
        qa, qb = a.reference_state(), b.reference_state()
        if (qa.shape != qb.shape or not np.array_equal(qa, qb) or not np.array_equal(a.free, b.free)
                or tuple(a.fixed) != tuple(b.fixed) or self.chamber_of[j] != self.chamber_of[i]
                or [repr(t) if type(t).__repr__ is not object.__repr__ else type(t) for t in a.terms]
                != [repr(t) if type(t).__repr__ is not object.__repr__ else type(t) for t in b.terms]):
            return False
        loads = dict(self.loads)
        own_a, own_b = self.membrane_loads(j, loads), self.membrane_loads(i, loads)
        if own_a != own_b:
            return False
        probe = qa.copy()
        wave = 1.0 + 0.05 * np.sin(np.arange(probe.size) * 0.7 + 0.3)
        probe[a.free] *= wave[a.free]
        own = {k: (v if k != "pressure" else 0.01 * a.mu * a.thickness / a.meridian.size) for k, v in own_a.items()}
        ea, eb = a.evaluate(probe, own), b.evaluate(probe.copy(), own)
        return (ea.energy == eb.energy and np.array_equal(ea.residual, eb.residual)
                and np.array_equal(ea.stiffness.lower(), eb.stiffness.lower())
                and a.measures(probe, own) == b.measures(probe.copy(), own))

    def same_as(self, i: int, states: Sequence[np.ndarray], loads: Mapping[str, float] | None = None):
        """The earlier membrane whose evaluation membrane i has in ``states`` (the membranes'
        states, :meth:`split`) under ``loads`` (resolved; None: whatever does not depend on them,
        volume and domain): its twin (:meth:`twin_of`) if both are in the same state bitwise and
        carry the same loads of their own, else None."""
        twin = self.twin_of()[i]
        if twin is None or states[i].tobytes() != states[twin].tobytes():     # bitwise (0.0 and -0.0 differ)
            return None
        if loads is not None and self.membrane_loads(i, loads) != self.membrane_loads(twin, loads):
            return None
        return twin

    # ----------------------------------------------------------------------------------------
    def evaluate(self, q: np.ndarray, loads: Mapping[str, float] | None = None, order: int = 2) -> Evaluation:
        """Total potential, gradient and block-diagonal band stiffness (one BandedMatrix) at q."""
        loads = self.resolve_loads(loads)
        states = self.split(q)
        parts = []
        for i, (m, qi) in enumerate(zip(self.membranes, states)):
            twin = self.same_as(i, states, loads)
            if twin is not None:
                self.reduced_evaluations += 1
            parts.append(parts[twin] if twin is not None else m.evaluate(qi, self.membrane_loads(i, loads), order))
        energy = sum(p.energy for p in parts)
        if order < 1:
            return Evaluation(energy, None, None, None)
        gradient = np.concatenate([p.gradient for p in parts])
        residual = np.concatenate([p.residual for p in parts])
        stiffness = None
        if order >= 2:
            stiffness = stack_bands([p.stiffness for p in parts], self.bandwidth)
        return Evaluation(energy, gradient, residual, stiffness, max(p.residual_floor for p in parts))

    def energy(self, q, loads=None) -> float:
        return self.evaluate(q, loads, order=0).energy

    def load_derivative(self, q: np.ndarray, name: str, loads: Mapping[str, float] | None = None) -> np.ndarray:
        """d(residual)/d(load ``name``) on the free degrees of freedom, shape (n_free,)."""
        loads = self.resolve_loads(loads)
        if name not in loads:
            raise SnapmemError(f"load {name!r}: this scene has no such load; it has {sorted(loads)}")
        out = np.zeros(self.n_free)
        for i, (m, qi) in enumerate(zip(self.membranes, self.split(q))):
            own = self.membrane_loads(i, loads)
            block = slice(self.free_offsets[i], self.free_offsets[i + 1])
            if name == f"voltage_{i + 1}":
                out[block] = m.load_derivative(qi, "voltage", own)
            elif self.chamber_of[i] is not None and name == self.pressure_name(self.chamber_of[i][0]):
                out[block] = self.chamber_of[i][1] * m.load_derivative(qi, "pressure", own)
        return out

    def chamber_volume(self, q: np.ndarray, c: int) -> float:
        """V_c = V_dead + sum_i s_i V_i [m^3] of chamber c."""
        return self.chamber_volume_and_gradient(q, c, gradient=False)[0]

    def volume_gradient(self, q: np.ndarray, c: int) -> np.ndarray:
        """dV_c/dq on the free degrees of freedom, shape (n_free,) [m^2]."""
        return self.chamber_volume_and_gradient(q, c)[1]

    def chamber_volume_and_gradient(self, q: np.ndarray, c: int, gradient: bool = True) -> tuple:
        """(V_c [m^3], dV_c/dq on the free degrees of freedom (n_free,) [m^2], or None) of chamber c.

        A membrane whose pressure work is the swept volume's (:class:`PressureWork`) takes the
        gradient from the compiled kernel and the volume from it, V = q . dV/dq / 3 (the swept
        volume is homogeneous of degree 3 in the coordinates; equal to the edge sum to rounding),
        without the kinematics a full evaluation builds; any other takes its volume and load
        derivative.
        """
        chamber = self.chambers[c]
        parts = self.split(q)
        total = chamber.dead_volume
        out = np.zeros(self.n_free) if gradient else None
        own = {}                                  # membrane -> its signed volume (for its twins)
        for i, s in zip(chamber.membranes, chamber.signs):
            m, qi = self.membranes[i], parts[i]
            block = slice(self.free_offsets[i], self.free_offsets[i + 1])
            twin = self.same_as(i, parts)
            if twin in own:                       # an identical membrane in the same state (same sign)
                total += own[twin]
                if gradient:
                    out[block] = out[self.free_offsets[twin]: self.free_offsets[twin + 1]]
                continue
            if self._swept[i]:
                # the swept volume is homogeneous of degree 3 in the coordinates (the formula
                # of snapmem.kernels.assembly.swept_volume), so V = q . dV/dq / 3 (Euler): one compiled pass gives both
                g = volume_gradient(qi, m.meridian.edges, qi.size)
                own[i] = s * float(g @ qi) / 3.0
                total += own[i]
                if gradient:
                    out[block] = s * g[m.free]
            else:
                own[i] = s * m.volume(qi)
                total += own[i]
                if gradient:
                    out[block] = -s * m.load_derivative(qi, "pressure", {"pressure": 0.0})
        return total, out

    def reduced(self, q: np.ndarray) -> bool | None:
        """Whether state q was evaluated by reduction (every membrane with an identical twin in
        the same state took its twin's evaluation, :meth:`same_as`); None for a scene without
        identical membranes."""
        twins = self.twin_of()
        if all(t is None for t in twins):
            return None
        states = self.split(q)
        return all(self.same_as(i, states) is not None for i, t in enumerate(twins) if t is not None)

    def volume(self, q: np.ndarray) -> float:
        """The first chamber's volume [m^3] (or the first membrane's, without chambers)."""
        return self.chamber_volume(q, 0) if self.chambers else self.membranes[0].volume(self.split(q)[0])

    # ----------------------------------------------------------------------------------------
    def inadmissible(self, q: np.ndarray):
        states = self.split(q)
        for i, (m, qi) in enumerate(zip(self.membranes, states)):
            if self.same_as(i, states) is not None:
                continue                           # its twin in the same state was admissible
            why = m.inadmissible(qi)
            if why is not None:
                return f"membrane {i + 1}: {why}"
        for c, chamber in enumerate(self.chambers):
            if chamber.kind.value == "gas" and not self.chamber_volume(q, c) > 0:
                return f"chamber {c + 1}: the gas volume is not positive"
        return None

    def max_step(self, q: np.ndarray, dq: np.ndarray) -> float:
        return min(m.max_step(qi, dqi) for m, qi, dqi in zip(self.membranes, self.split(q), self.split(dq)))

    def measures(self, q: np.ndarray, loads=None) -> dict:
        """volume (first chamber's total), u_max, stretch_max, min_tension, taut over all membranes,
        and each membrane's measures with its number as a suffix (``volume_1``, ``stretch_2``)."""
        loads = self.resolve_loads(loads)
        states = self.split(q)
        own = []
        for i, (m, qi) in enumerate(zip(self.membranes, states)):
            twin = self.same_as(i, states, loads)
            own.append(dict(own[twin]) if twin is not None else m.measures(qi, self.membrane_loads(i, loads)))
        out = {"volume": self.volume(q), "u_max": max(o["u_max"] for o in own),
               "stretch_max": max(o["stretch_max"] for o in own),
               "min_tension": min(o["min_tension"] for o in own), "taut": all(o["taut"] for o in own)}
        for c in range(1, len(self.chambers)):
            out[f"volume_chamber_{c + 1}"] = self.chamber_volume(q, c)
        for i, o in enumerate(own):
            out.update({f"{k}_{i + 1}": v for k, v in o.items()})
        return out

    def __getattr__(self, name):
        """What a single-membrane Scene has and this one lacks (dynamics, contact, export): one clear error."""
        if name.startswith("__"):
            raise AttributeError(name)
        raise SnapmemError(f"scene {self.__dict__.get('name', 'multi')!r} has several membranes: {name!r} is not "
                           "available for it yet (statics, continuation and dynamics are)")

    def __repr__(self):
        return (f"MultiScene({self.name!r}, membranes={len(self.membranes)}, "
                f"chambers={[c.kind.value for c in self.chambers]}, loads={self.loads})")


def stack_bands(blocks: Sequence[BandedMatrix], bandwidth: int) -> BandedMatrix:
    """The block-diagonal matrix of band matrices, as one band matrix of half-bandwidth ``bandwidth``
    (>= each block's): lower bands side by side, no entry across two blocks."""
    n = sum(B.n for B in blocks)
    lower = np.zeros((bandwidth + 1, n))
    start = 0
    for B in blocks:
        own = B.lower()
        for d in range(min(B.b, bandwidth) + 1):
            lower[d, start: start + B.n - d] = own[d, : B.n - d]   # entries past the block stay 0
        start += B.n
    return BandedMatrix.from_lower(lower, bandwidth)

