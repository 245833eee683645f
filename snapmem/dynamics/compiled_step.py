"""A time step's whole Newton solve in one compiled call, for the scenes whose terms declare a
compiled form.

Why it exists: a time step of a small scene is a few Newton iterations of little compiled
arithmetic each, and the general path (``Scene.evaluate`` with its node terms,
``snapmem.solvers.newton.newton``, the bordered solve, the domain checks) spends far more in the
Python calls around it (the measurements: docs/performance.md). Here the same arithmetic runs in
one numba kernel per time step, built from the same building blocks (``snapmem.kernels``): the
stretches, the law's density, the fused membrane assembly, the contact barriers, the band LDL^T
with the bodies' Schur complement, the step limits and domain checks, and Newton's line search on
the step's incremental potential with the Python Newton's own rules (``snapmem.solvers.rules``).
Every robot's steps, iteration counts and events are those of the general path.

What it covers: a scene whose every term declares what the kernel needs (``Term.compiled``,
see :mod:`snapmem.model.terms`): one stretching law of a kind in snapmem.kernels.laws (possibly
mounted prestretched), at most one set of viscous networks (snapmem.model.viscous), electric
terms, at most one pressure work, contacts with a linear gap (rod, shell, plane) and balls in edge
mode (with or without a body of their own); and the 'energy' line search of
:class:`snapmem.dynamics.driver.DynamicsOptions`. :meth:`CompiledStep.of` returns None otherwise
(or on :func:`snapmem.reference_path`), and the general path runs.

The modules: :mod:`snapmem.dynamics.compiled_assembly` (the potential, its tangent, the domain
and step limits), :mod:`snapmem.dynamics.compiled_newton` (the solve),
:mod:`snapmem.dynamics.compiled_measures` (recorded frames). A step whose tangent the LDL^T cannot
factor stably (rare: the inertia M / h^2 makes K positive definite but for very large steps) is
handed back, and the general Newton (with its pivoted LU) takes it.
"""

from __future__ import annotations

import numpy as np

from snapmem._lazy import inlined
from snapmem.dynamics.compiled_assembly import (TANGENT, Balls, GeneralLaw, LinearContacts, Plan, Viscous,
                                                assemble_entry, contact_gaps, start_networks)
from snapmem.dynamics.compiled_measures import frames_measures
from snapmem.dynamics.compiled_newton import HANDED_BACK, OUTCOMES, CONVERGED, time_step
from snapmem.dynamics.step_arithmetic import MIDPOINT, NO_OUTCOME
from snapmem.kernels.laws import LAW_LINEAR
from snapmem.kernels.switch import compiled
from snapmem.model.contact import contact_names
from snapmem.model.terms import (BallDeclaration, ElectricDeclaration, LawDeclaration, LinearContactDeclaration,
                                 PressureDeclaration, ViscousDeclaration)
from snapmem.solvers.newton import NewtonReport


#: The exponent of :func:`electric_coefficient`, 2.0, passed as a number: numba folds a constant
#: exponent 2 into phi * phi, which rounds differently from the C library's pow (Python's float
#: power) in about 0.1% of values.
SQUARE = 2.0


def electric_coefficient(phi, coefficients, square):
    """a_el = sum over the electric terms of c phi^square [Pa] (square = :data:`SQUARE`): the
    electric coefficient the kernels take at voltage phi [V], c = eps / (2 H^2) of each term.
    Written once for Python (:meth:`CompiledStep.kernel_loads`) and the compiled run
    (:data:`electric_coefficient_compiled`)."""
    a_el = 0.0
    for c in coefficients:
        a_el = a_el + c * phi ** square
    return a_el


#: :func:`electric_coefficient` for compiled code (inlined; Python calls the function itself).
electric_coefficient_compiled = inlined(electric_coefficient)


def _ints(values) -> np.ndarray:
    return np.ascontiguousarray(values, dtype=np.int64)


class CompiledStep:
    """The compiled Newton solve of a time step's incremental potential for one scene.

    Build with :meth:`of` (None when a term of the scene declares no compiled form); then
    :meth:`solve` takes the place of ``newton(assemble, guess, ...)`` in the stepper.
    """

    def __init__(self, scene, plan: Plan, terms: tuple, electric: tuple, pressure: bool, contact_slots: list,
                 viscous=None):
        self.scene, self.plan = scene, plan
        # the viscous networks' term (snapmem.model.viscous) and the kernels' arrays of it, or None
        self._viscous_term = viscous
        self.viscous = None if viscous is None else Viscous(
            visc_mu=np.array(viscous.moduli, dtype=float), visc_jlim=np.array(viscous.jlims, dtype=float),
            visc_c=np.zeros(viscous.networks), zeta_hat=np.zeros((viscous.networks, 2, plan.edges.shape[0])),
            zeta_warm=np.zeros((viscous.networks, 2, plan.edges.shape[0])),
            zeta_warm_exp=np.ones((viscous.networks, 2, plan.edges.shape[0])))
        # in a step: the same, on the open step's own anchor array (the stepper keeps one for the run:
        # made again only when that array changes) and the term's moduli, with no copies
        self._step_networks = None
        # (general_law, linear, balls): those terms, None for a kind the scene has not, so that the
        # kernels compile only the terms the scene has (compiled_assembly)
        self.terms = terms
        self._electric = electric            # (eps / (2 H^2)) of each electric term
        self.has_pressure = pressure
        # (output name, index in the kernel's contact arrays) of every contact, in the scene's order
        self._contacts = list(zip(contact_names(scene), contact_slots))
        # the networks' step the kernel opens and closes itself (take_network_step), or None; and
        # the state y of the last solve whose kernel wrote that step's new state
        self._network_step = None
        self.network_step_closed_at = None
        # time_step's compiled entry point for these terms, by (networks is None, network_step is None)
        self._entries = {}
        # the arguments of time_step that stay the same over a run (the stepper's mass and damping
        # arrays, its tolerances and options): the key they were made for and the two parts of the
        # argument tuple around the step's own ones (built once, not at every step)
        self._fixed_key = None
        self._fixed_arrays = self._fixed_tail = ()
        self._middle = (plan, *terms)
        # (y, q_{n+1}, v_{n+1}, a_{n+1}, change, largest) of the last solve that was asked for its
        # scheme's outcome and converged (step_arithmetic.step_outcome), else None
        self.outcome = None

    @classmethod
    def of(cls, scene) -> "CompiledStep | None":
        """The compiled step of ``scene`` from its terms' declarations, or None if a term has none
        (or on the reference path)."""
        if not compiled():
            return None
        found = {LawDeclaration: [], ElectricDeclaration: [], PressureDeclaration: [], ViscousDeclaration: []}
        for term in scene.density_terms + scene.edge_terms:
            declared = term.compiled(scene)
            if type(declared) not in found:
                return None
            found[type(declared)].append(declared)
        law, electric, pressure, viscous = found.values()
        if len(law) != 1 or len(pressure) > 1 or len(viscous) > 1:
            return None
        linear, balls, slots = [], [], []
        for term, bodies in zip(scene.node_terms, scene.dofs.body_slices):
            declared = term.compiled(scene, bodies)
            if isinstance(declared, LinearContactDeclaration):
                slots.append((False, len(linear)))
                linear.append(declared)
            elif isinstance(declared, BallDeclaration):
                slots.append((True, len(balls)))
                balls.append(declared)
            else:
                return None
        plan, terms = _plan(scene, law[0], linear, balls)
        slots = [len(linear) + i if ball else i for ball, i in slots]      # every node term is a contact here
        return cls(scene, plan, terms, tuple(d.coefficient for d in electric), bool(pressure), slots,
                   viscous[0].term if viscous else None)

    def kernel_loads(self, loads) -> tuple:
        """(pressure [Pa], a_el [Pa]) the kernels take for ``loads``: a_el = sum of eps/(2 H^2) phi^2
        over the electric terms. The compiled chamber step calls it per membrane."""
        pressure = float(loads["pressure"]) if self.has_pressure else 0.0
        a_el = electric_coefficient(float(loads["voltage"]), self._electric, SQUARE) if self._electric else 0.0
        return pressure, a_el                 # float64 for numba, always

    @property
    def electric(self) -> tuple:
        """The electric terms' coefficients eps / (2 H^2) [F/m^3] (empty without)."""
        return self._electric

    def assemble(self, q, loads, inertia=None, anchor=None, momentum=None):
        """Energy, residual (n_free,), lower band (b + 1, n_band), border (k, n_band), corner (k, k)
        and rounding floor of the incremental potential at q (the scene's own without ``inertia``):
        the kernel's assembly, exposed for the tests that compare it with ``Scene.evaluate``."""
        n_free = self.plan.free.size
        inertia = np.zeros(n_free) if inertia is None else inertia
        anchor = q if anchor is None else anchor
        momentum = np.zeros(n_free) if momentum is None else momentum
        networks = self._open_networks()
        if networks is not None:
            start_networks(networks)
        return assemble_entry(q, self.plan, *self.terms, networks, *self.kernel_loads(loads), inertia, anchor, momentum,
                              TANGENT)

    @property
    def viscous_term(self):
        """The scene's viscous networks' term the kernel covers (snapmem.model.viscous), or None."""
        return self._viscous_term

    def take_network_step(self, step) -> None:
        """The next solve opens and closes the networks' step itself: ``step`` a
        :data:`~snapmem.dynamics.compiled_assembly.NetworkStep` (None: the caller does it). The
        term's open step must name the same anchor array the kernel writes (``begin_step`` with
        the step's zeta_hat array, which the kernel fills before any solve, a handed-back one too)."""
        self._network_step = step

    def _open_networks(self):
        """The viscous networks' arrays for the term's present state (None without networks): in an
        open step its c = eta / h and anchor zeta_hat (the local solves start there); outside a
        step the internal stretches held at their state (limit 'instantaneous') or no networks
        (moduli 0: 'relaxed')."""
        v, term = self.viscous, self._viscous_term
        if v is None:
            return None
        step = term.open_step
        if step is None:
            v.visc_c[:] = 0.0
            v.zeta_hat[:] = term.state(self.plan.edges.shape[0])
            v.visc_mu[:] = 0.0 if term.limit == "relaxed" else term.moduli
            return v
        h, zeta_hat = step
        s = self._step_networks
        if s is None or s.zeta_hat is not zeta_hat or s.visc_mu is not term.moduli:
            hat = np.ascontiguousarray(zeta_hat, dtype=float)
            s = Viscous(visc_mu=np.ascontiguousarray(term.moduli, dtype=float), visc_jlim=v.visc_jlim,
                        visc_c=np.empty_like(v.visc_c), zeta_hat=hat, zeta_warm=np.empty_like(hat),
                        zeta_warm_exp=np.empty_like(hat))
            self._step_networks = s if hat is zeta_hat and s.visc_mu is term.moduli else None
        if self._network_step is None:      # else the kernel sets c = eta / h (open_network_step)
            np.divide(term.viscosities, h, out=s.visc_c)
        return s

    def measures_many(self, Q, loads: list, xi=None) -> tuple:
        """Potential energy [J], volume [m^3] and smallest contact gap [m] of every state (rows of Q,
        each with its loads), each (T,), and the contact report's columns ``<name>_force`` [N] and
        ``<name>_gap`` [m]: what ``Scene.energy``, ``Scene.volume``, :meth:`min_gap` and
        :func:`snapmem.model.contact.contact_report` give, in one compiled call. With viscous
        networks, ``xi`` (T, K, 2, E) are the frames' internal stretches: their stored energy joins
        the potential."""
        coefficients = np.array([self.kernel_loads(each) for each in loads], dtype=float).reshape(-1, 2)   # (pressure, a_el)
        energy, volume, forces, gaps = frames_measures(np.ascontiguousarray(Q, dtype=float), self.plan, *self.terms,
                                                       coefficients[:, 0].copy(), coefficients[:, 1].copy())
        columns = {}
        for name, i in self._contacts:
            columns[f"{name}_force"] = forces[:, i]
            columns[f"{name}_gap"] = gaps[:, i]
        smallest = gaps.min(axis=1) if gaps.shape[1] else np.full(len(Q), np.inf)
        term = self._viscous_term
        if term is not None and xi is not None:
            weight = self.scene.weight
            energy = energy + np.array([term.stored_energy(self.scene.kinematics(q), np.log(x), weight)
                                        for q, x in zip(Q, xi)])
        return energy, volume, smallest, columns

    def min_gap(self, q) -> float:
        """Smallest gap of all contacts at q [m] (inf without contact)."""
        gaps = contact_gaps(q, self.plan, *self.terms[1:])
        return float(gaps.min()) if gaps.size else np.inf

    def solve(self, anchor, velocity, h, loads, fallback, mass, damping, tol, size, options, outcome=None,
              increment_tol=0.0):
        """The time step of ``snapmem.dynamics.driver._Stepper.solve`` (which documents it): Newton on the
        incremental potential of step h from (anchor, velocity), with ``mass`` and ``damping`` on
        the free degrees of freedom, from the guess anchor + h velocity (``fallback``, the present
        state, if the guess is outside the domain). (y, NewtonReport), or None to hand the step
        back to the general path. ``mass``, ``damping``, ``tol``, ``size``, ``options`` and
        ``increment_tol`` (the Newton increment test's, snapmem.solvers.newton.newton's) are the
        run's: their part of the kernel's arguments is made again only when one of them changes
        (``mass`` and ``damping`` by identity: not rewritten in place between steps).

        ``outcome``: (kind, step, a_previous) of the scheme's outcome of the step
        (snapmem.dynamics.step_arithmetic.step_outcome), computed in the same call once Newton has
        converged and kept as :attr:`outcome` with its y (None: not asked for)."""
        pressure, a_el = self.kernel_loads(loads)
        networks = self._open_networks()
        open_step = None if networks is None else self._viscous_term.open_step
        network_step = None if open_step is None else self._network_step
        self._network_step = None                     # one solve's
        plain = np.ascontiguousarray        # the arrays as the compiled entry point types them (no copies)
        fixed = self._fixed_key             # the run's own arguments: the same objects at every step
        if (fixed is None or fixed[0] is not mass or fixed[1] is not damping or fixed[2] is not options
                or fixed[3:] != (tol, size, increment_tol)):
            self._fixed_key = (mass, damping, options, tol, size, increment_tol)
            self._fixed_arrays = (plain(mass, dtype=float), plain(damping, dtype=float))
            self._fixed_tail = (float(tol), float(size), float(increment_tol), int(options.max_iterations),
                                int(options.max_cuts))
        anchor = plain(anchor, dtype=float)
        kind, step, a_previous = (NO_OUTCOME, 0.0, anchor) if outcome is None else outcome
        args = ((anchor, plain(velocity, dtype=float), float(h)) + self._fixed_arrays
                + (plain(fallback, dtype=float),) + self._middle + (networks, network_step, pressure, a_el)
                + self._fixed_tail + (kind, float(step), plain(a_previous, dtype=float)))
        key = (networks is None, network_step is None)
        entry = self._entries.get(key)
        if entry is None:
            y, code, iterations, cuts, norm, q_new, v_new, a_new, change, largest = time_step(*args)
            self._entries[key] = _entry_point(time_step, args)
        else:
            y, code, iterations, cuts, norm, q_new, v_new, a_new, change, largest = entry(*args)
        self.outcome = None if kind == NO_OUTCOME or code != CONVERGED else (
            y, q_new if kind == MIDPOINT else y, v_new, a_new, change, largest)
        if network_step is not None and networks.zeta_hat is not open_step[1]:
            open_step[1][...] = networks.zeta_hat    # the kernel's anchor (a copy's): the term's
        if code == HANDED_BACK:
            return None
        if open_step is not None:                   # zeta*(y): the driver's close reads it
            self._viscous_term.hand_over(y, networks.zeta_warm)     # read by the close, before the next solve
            if network_step is not None and code == CONVERGED:
                self.network_step_closed_at = y         # its new state and dissipation are written
        status, reason = OUTCOMES[code]
        return y, NewtonReport(code == CONVERGED, int(iterations), float(norm), reason, int(cuts), status=status)


def _entry_point(kernel, args: tuple):
    """The compiled function ``kernel`` (a numba dispatcher, or a lazy kernel with one) ran for
    ``args`` (it has been called with them), to be called directly with arguments of the same
    types: numba's dispatcher types every argument at every call (here some 45 arrays in the
    plan's and terms' tuples, ~10 us a call: a few percent of a small scene's step), although
    only the caller's arrays change, never their types.

    Found without typing the arguments (numba.typeof of the tuples takes ~0.4 ms, a run's cost):
    the one compiled version whose arguments are None where ``args`` are. If several versions
    share that pattern (arrays of other layouts), the dispatcher is returned: it chooses."""
    dispatcher = getattr(kernel, "dispatcher", kernel)
    if not hasattr(dispatcher, "overloads"):            # a plain function (a test's stand-in)
        return kernel
    pattern = tuple(a is None for a in args)
    overloads = dispatcher.overloads
    key = (id(dispatcher), pattern)
    known = _ENTRIES.get(key)
    if known is not None and known[0] == len(overloads):    # no version compiled since: the same one
        return known[1]
    matching = [compiled for signature, compiled in overloads.items()
                if len(signature) == len(args)
                and tuple(type(t).__name__ == "NoneType" for t in signature) == pattern]
    entry = matching[0].entry_point if len(matching) == 1 else dispatcher
    _ENTRIES[key] = (len(overloads), entry)
    return entry


#: (id of the dispatcher, None pattern) -> (its number of compiled versions then, the entry point)
#: of :func:`_entry_point` (matching the versions' types costs ~0.15 ms: a short run's 1%)
_ENTRIES: dict = {}


def _plan(scene, law: LawDeclaration, linear: list, balls: list) -> tuple:
    """The kernels' arrays for ``scene`` with the declared law, linear contacts and balls: the
    :class:`Plan` and the kernels' (general_law, linear, balls), None for a kind the scene has not."""
    m, dofs = scene.meridian, scene.dofs
    n_nodes, n_edges = m.nodes, m.edges.shape[0]
    plan = Plan(
        edges=_ints(m.edges), inv_length=m.inverse_length, inv_mid_radius=m.inverse_mid_radius, weight=scene.weight,
        law_kind=law.kind, law_params=np.array(law.params, dtype=float),
        law_stretch=None if tuple(law.prestretch) == (1.0, 1.0) else np.array(law.prestretch, dtype=float),
        hess_index=_ints(dofs.hess_index), band_size=int(dofs.band_size), n_band=int(dofs.n_band),
        bandwidth=int(dofs.bandwidth), free=_ints(dofs.free), radius_dofs=_ints(dofs.radius_dofs),
        n_node_dofs=int(dofs.n_node_dofs), n_bodies=int(dofs.n_bodies),
        edge_dofs=_ints(dofs.edge_dofs), edge_pos=_ints(dofs.edge_pos), node_hess=_ints(dofs.node_hess))
    general_law = None if law.kind == LAW_LINEAR else GeneralLaw(plan.law_kind, plan.law_params)
    linear_contacts = None if not linear else LinearContacts(
        lin_nodes=np.concatenate([_ints(c.nodes) for c in linear]),
        lin_ptr=np.cumsum([0] + [c.nodes.size for c in linear]).astype(np.int64),
        lin_axis=np.array([c.axis for c in linear], dtype=np.int64),
        lin_sign=np.array([c.sign for c in linear], dtype=float),
        lin_offset=np.array([c.offset for c in linear], dtype=float),
        lin_dhat=np.array([c.dhat for c in linear], dtype=float),
        lin_coef=np.array([c.coef for c in linear], dtype=float).reshape(len(linear), n_nodes))
    # balls is None also says there are no bodies (time_step then solves the band alone)
    ball_contacts = None if not balls and not plan.n_bodies else Balls(
        ball_radius=np.array([b.radius for b in balls], dtype=float),
        ball_dhat=np.array([b.dhat for b in balls], dtype=float),
        ball_coef=np.array([b.coef for b in balls], dtype=float).reshape(len(balls), n_edges),
        ball_z0=np.array([b.z0 for b in balls], dtype=float),
        ball_dof=np.array([b.dof for b in balls], dtype=np.int64),
        ball_col=np.array([b.dof - dofs.n_node_dofs if b.dof >= 0 else -1 for b in balls], dtype=np.int64),
        ball_weight=np.array([b.weight for b in balls], dtype=float))
    return plan, (general_law, linear_contacts, ball_contacts)
