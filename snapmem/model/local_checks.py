"""Local well-posedness of the membrane model at a state: strong ellipticity and tension, per edge.

A membrane's energy W(F), F the 3x2 map of the tangent plane, is strongly elliptic (rank-one
convex) where d2/de2 W(F + e a (x) N) > 0 for every a in R^3 and N in R^2. For an isotropic W
of the principal stretches (lam1, lam2), the incompressible membrane's W_eff with the electric
term included, the perturbations split into two families:

- out of the plane (a normal to the surface): d2W = W1 N1^2 / lam1 + W2 N2^2 / lam2, so the
  principal tensions T1 = (H/lam2) W1, T2 = (H/lam1) W2 must be positive (tension field
  theory: where they are not, the membrane wrinkles);
- in the plane: the acoustic tensor of the 2D energy W(lam1, lam2) in the principal frame is
  [[W11 n1^2 + a n2^2, (W12 + b - a) n1 n2], [sym, a n1^2 + W22 n2^2]] with
  a = (lam1 W1 - lam2 W2)/(lam1^2 - lam2^2) and b = (W1 - W2)/(lam1 - lam2). It is positive
  definite for every N = (n1, n2) iff (Knowles & Sternberg 1976)

      W11 > 0,  W22 > 0,  a > 0,
      sqrt(W11 W22) + W12 + b > 0,
      sqrt(W11 W22) - W12 + (W1 + W2)/(lam1 + lam2) > 0.

At lam1 = lam2 = lam the quotients take their limits a = (W1 + lam (W11 - W12)) / (2 lam) and
b = W11 - W12, and the conditions reduce to W11 > 0 and a > 0; for the inflated sphere W11 = 0
comes first (MODEL.md section 7: the limit n -> infinity of the P_n criterion).

The margin of an edge is the smallest of the in-plane conditions' left-hand sides divided by
the law's shear modulus (dimensionless); the model is ill-posed where it is <= 0. A membrane
mounted prestretched (:class:`~snapmem.model.prestretch.Prestretched`) is checked in the total
stretches Lam_i = lp_i lam_i, where W_eff is isotropic.

The failure checks of a real dielectric elastomer (issue 15) are here too, as margins that fail
at 1 (:func:`failure_margins`, the columns ``breakdown_margin`` and ``rupture_margin`` of branch
tables and trajectories):

- electrical breakdown: the true field E = |phi| / h = |phi| lam1 lam2 / H of every edge against
  the breakdown strength E_B = E_breakdown (Lam1 Lam2)^breakdown_exponent, a power law in the
  area stretch relative to the stress-free state (so that it rises with prestretch, as VHB's
  does); ``breakdown_margin`` = min over edges of E_B / E (inf without a voltage or without an
  ``E_breakdown``);
- rupture: ``rupture_margin`` = stretch_limit / (largest total principal stretch Lam_i over the
  edges) (inf without a ``stretch_limit``).

The scene parameters ``E_breakdown`` [V/m], ``breakdown_exponent`` and ``stretch_limit`` are read
from ``scene.parameters`` (:class:`FailureLimits`); None (the default) means no check.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from snapmem.errors import SnapmemError
from snapmem.model.materials import Density
from snapmem.model.prestretch import prestretches, total_density

#: |lam1 - lam2| / lam below which the quotients a and b take their equal-stretch limits (the
#: quotients lose digits as 1 / |lam1 - lam2|; the limits are off by O(|lam1 - lam2|))
EQUAL_STRETCH = 1e-6


def ellipticity_margins(lam1: np.ndarray, lam2: np.ndarray, dens: Density, modulus: float) -> np.ndarray:
    """The in-plane strong-ellipticity margin of every edge (module docstring), shape (E,).

    Parameters
    ----------
    lam1, lam2 : ndarray (E,)
        Meridional and hoop stretches.
    dens : Density
        W_eff and its derivatives at (lam1, lam2) [Pa], electric term included.
    modulus : float
        Shear modulus [Pa] the margins are divided by.

    Returns
    -------
    ndarray (E,)
        min over the five conditions of their left-hand side / modulus; > 0 where elliptic.
    """
    w1, w2, w11, w12, w22 = dens.w1, dens.w2, dens.w11, dens.w12, dens.w22
    diff = lam1 - lam2
    mean = 0.5 * (lam1 + lam2)
    equal = np.abs(diff) <= EQUAL_STRETCH * mean
    safe = np.where(equal, 1.0, diff)
    a = np.where(equal, (0.5 * (w1 + w2) + mean * (w11 - w12)) / (2.0 * mean),
                 (lam1 * w1 - lam2 * w2) / (safe * (lam1 + lam2)))
    b = np.where(equal, 0.5 * (w11 + w22) - w12, (w1 - w2) / safe)
    root = np.sqrt(np.maximum(w11 * w22, 0.0)) * np.where((w11 > 0) & (w22 > 0), 1.0, -1.0)
    conditions = np.stack([w11, w22, a, root + w12 + b, root - w12 + (w1 + w2) / (lam1 + lam2)])
    return conditions.min(axis=0) / modulus


@dataclass(frozen=True)
class LocalState:
    """The local checks of one state.

    Attributes
    ----------
    ellipticity : float
        Smallest in-plane ellipticity margin over the edges (dimensionless, > 0 where elliptic).
    ellipticity_edge : int
        The edge where it is smallest.
    tension : float
        Smallest principal tension over the edges [N/m] (> 0 where taut).
    tension_edge : int
        The edge where it is smallest.
    stretch : float
        Largest principal stretch at ``ellipticity_edge`` (relative to the stress-free state).
    """

    ellipticity: float
    ellipticity_edge: int
    tension: float
    tension_edge: int
    stretch: float

    @property
    def elliptic(self) -> bool:
        return self.ellipticity > 0.0

    @property
    def taut(self) -> bool:
        return self.tension > 0.0


def local_state(scene, q: np.ndarray, loads=None, with_tension: bool = True) -> LocalState | None:
    """The ellipticity and tension checks of the scene's membrane at state q [m] under ``loads``
    (resolved or None for the scene's); None if the scene has no membrane energy.
    ``with_tension``: False leaves the tension out (NaN; a trace has it among its measures).
    A scene of several membranes (``scene.membranes``) gives its least elliptic membrane's state
    (edges numbered within that membrane) with the smallest tension over all of them."""
    if hasattr(scene, "membranes"):
        loads = scene.resolve_loads(loads)
        parts, states = scene.split(q), []
        for i, (m, qi) in enumerate(zip(scene.membranes, parts)):
            twin = scene.same_as(i, parts, loads)          # an identical membrane in the same state
            states.append(states[twin] if twin is not None
                          else local_state(m, qi, scene.membrane_loads(i, loads), with_tension))
        states = [s for s in states if s is not None]
        if not states:
            return None
        least = min(states, key=lambda s: s.ellipticity)
        slack = min(states, key=lambda s: s.tension if with_tension else 0.0)
        return LocalState(least.ellipticity, least.ellipticity_edge, slack.tension, slack.tension_edge, least.stretch)
    kin = scene.kinematics(q)
    dens = scene.density(kin, scene.resolve_loads(loads))
    if dens is None:
        return None
    lp1, lp2 = scene_prestretches(scene)
    lam1, lam2 = lp1 * kin.lam1, lp2 * kin.lam2                   # total stretches (mounted ones if lp = 1)
    margins = ellipticity_margins(lam1, lam2, total_density(dens, lp1, lp2), scene.mu)
    ie = int(np.argmin(margins))
    tension, it = float("nan"), -1
    if with_tension:
        t1, t2 = scene.tensions(q, loads)
        smallest = np.minimum(t1, t2)
        it = int(np.argmin(smallest))
        tension = float(smallest[it])
    return LocalState(float(margins[ie]), ie, tension, it, float(max(lam1[ie], lam2[ie])))


def scene_prestretches(scene) -> tuple[float, float]:
    """(lp1, lp2) of the scene's stretching law ((1, 1) if it is not prestretched or has none)."""
    for term in scene.density_terms:
        law = getattr(term, "law", None)
        if law is not None:
            return prestretches(law)
    return 1.0, 1.0


@dataclass(frozen=True)
class FailureLimits:
    """The failure limits of a scene's material (module docstring); None: not checked.

    Attributes
    ----------
    E_breakdown : float or None
        Breakdown strength of the stress-free material [V/m] (the scene's voltage unit per its
        length unit).
    breakdown_exponent : float
        Exponent k of E_B = E_breakdown (Lam1 Lam2)^k.
    stretch_limit : float or None
        Largest principal stretch relative to the stress-free state before rupture.
    """

    E_breakdown: float | None = None
    breakdown_exponent: float = 0.0
    stretch_limit: float | None = None

    @classmethod
    def of(cls, scene) -> "FailureLimits":
        """The limits in ``scene.parameters`` (absent ones: not checked)."""
        p = scene.parameters
        return cls(p.get("E_breakdown"), float(p.get("breakdown_exponent") or 0.0), p.get("stretch_limit"))

    @property
    def any(self) -> bool:
        return self.E_breakdown is not None or self.stretch_limit is not None


def breakdown_margins(lam1, lam2, voltage: float, thickness: float, limits: FailureLimits,
                      lp1: float = 1.0, lp2: float = 1.0) -> np.ndarray:
    """E_B / E of every edge, shape (E,): E = |phi| lam1 lam2 / H the true field [V/m] (lam the
    stretches relative to the mounted state, H its thickness [m]), E_B = E_breakdown
    (Lam1 Lam2)^k at the total stretches Lam_i = lp_i lam_i; inf where E = 0 or unchecked."""
    if limits.E_breakdown is None or voltage == 0.0:
        return np.full(np.shape(lam1), np.inf)
    area = lam1 * lam2
    strength = limits.E_breakdown * (lp1 * lp2 * area) ** limits.breakdown_exponent
    return strength * thickness / (abs(voltage) * area)


def _limits(scene) -> FailureLimits:
    limits = scene.__dict__.get("_failure_limits")
    if limits is None:
        limits = scene._failure_limits = FailureLimits.of(scene)
    return limits


#: the outputs :func:`edge_values` gives per edge, each the minimum over edges of a smooth
#: function of the edge's stretches: name -> the level it fails at
EDGE_MEASURES = {"breakdown_margin": 1.0, "rupture_margin": 1.0, "min_tension": 0.0, "ellipticity": 0.0}


def edge_values(scene, q: np.ndarray, loads, name: str) -> np.ndarray:
    """Per edge (E,), the quantity whose minimum over the edges is the output ``name`` (one of
    :data:`EDGE_MEASURES`): E_B / E, stretch_limit / largest total stretch, the smaller principal
    tension [N/m], the ellipticity margin. ``loads`` resolved or None."""
    kin = scene.kinematics(q)
    lp1, lp2 = scene_prestretches(scene)
    limits = _limits(scene)
    if name == "breakdown_margin":
        voltage = scene.resolve_loads(loads).get("voltage", 0.0)
        return breakdown_margins(kin.lam1, kin.lam2, voltage, scene.thickness, limits, lp1, lp2)
    if name == "rupture_margin":
        if limits.stretch_limit is None:
            return np.full(kin.lam1.shape, np.inf)
        return limits.stretch_limit / np.maximum(lp1 * kin.lam1, lp2 * kin.lam2)
    if name == "min_tension":
        return np.minimum(*scene.tensions(q, loads))
    if name == "ellipticity":
        dens = scene.density(kin, scene.resolve_loads(loads))
        return ellipticity_margins(lp1 * kin.lam1, lp2 * kin.lam2, total_density(dens, lp1, lp2), scene.mu)
    raise SnapmemError(f"measure {name!r}: not a per-edge check; must be one of {', '.join(EDGE_MEASURES)}")


def failure_margins(scene, q: np.ndarray, loads=None) -> dict:
    """The failure columns of state q [m] under ``loads`` (resolved or None): ``breakdown_margin``
    and ``rupture_margin`` (module docstring; each fails at 1, inf where unchecked)."""
    limits = _limits(scene)
    if not limits.any:
        return {"breakdown_margin": np.inf, "rupture_margin": np.inf}
    return {name: float(edge_values(scene, q, loads, name).min()) for name in ("breakdown_margin", "rupture_margin")}


def failure_margins_many(scene, Q: np.ndarray, voltages: np.ndarray) -> dict:
    """:func:`failure_margins` of many states at once (a trajectory's frames): Q (T, n_dof) [m],
    voltages (T,) [V]; arrays (T,). The stretches come straight from the node coordinates, so
    this costs a few array operations over (T, E), not T assemblies."""
    limits = _limits(scene)
    frames = Q.shape[0]
    if not limits.any:
        return {"breakdown_margin": np.full(frames, np.inf), "rupture_margin": np.full(frames, np.inf)}
    m = scene.meridian
    n = scene.n_node_dofs
    r, z = Q[:, 0:n:2], Q[:, 1:n:2]
    a, b = m.edges[:, 0], m.edges[:, 1]
    lam1 = np.hypot(r[:, b] - r[:, a], z[:, b] - z[:, a]) * m.inverse_length
    lam2 = 0.5 * (r[:, a] + r[:, b]) * m.inverse_mid_radius
    lp1, lp2 = scene_prestretches(scene)
    breakdown = np.full(frames, np.inf)
    if limits.E_breakdown is not None:
        voltages = np.abs(np.asarray(voltages, dtype=float))
        area = lam1 * lam2
        strength = limits.E_breakdown * (lp1 * lp2 * area) ** limits.breakdown_exponent
        with np.errstate(divide="ignore"):
            breakdown = (strength * scene.thickness / area).min(axis=1) / voltages
    rupture = np.full(frames, np.inf)
    if limits.stretch_limit is not None:
        rupture = limits.stretch_limit / np.maximum(lp1 * lam1, lp2 * lam2).max(axis=1)
    return {"breakdown_margin": breakdown, "rupture_margin": rupture}
