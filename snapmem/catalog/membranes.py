"""The validation scenes (plate, balloon, torus) and the parameters and assembly every membrane
scene shares.

The defaults of ``plate``, ``balloon`` and ``torus`` are the paper's validation cases (MODEL.md
section 6), in normalised units (mu = 1, so pressures are p_hat and stresses are in units of mu).
The material parameters come from the registered laws (snapmem.model.materials): a scene lists
``material``, the law constants ``c1``, ``c2``, ``c3``, its shear modulus ``mu`` and ``Jlim``,
and takes any other parameter of the law chosen (see snapmem.catalog.registry).
"""

from __future__ import annotations

import numpy as np

from snapmem.catalog.registry import Parameter, SceneSpec, register
from snapmem.errors import SnapmemError
from snapmem.model.chambers import Chamber, ChamberKind
from snapmem.model.constraints import CentreOfMassHeight
from snapmem.model.dofs import node_areas
from snapmem.model.materials import LAWS, Law, law_class, law_name
from snapmem.model.prestretch import Prestretched
from snapmem.model.meridian import Meridian, disc, sphere, torus
from snapmem.model.multi import MultiScene
from snapmem.model.parameters import MAX_NODES, nodes_note
from snapmem.model.scene import Scene
from snapmem.model.terms import Electric, PressureWork, Stretching
from snapmem.model.viscous import VISCOUS_LIMITS, ViscousNetworks

def common_parameters(nodes: int, H=None) -> tuple:
    """``nodes`` and the reference thickness ``H`` [m] (None: set by the scene's defaults)."""
    return (Parameter("nodes", nodes, "", "number of meridian nodes", int, minimum=3, maximum=MAX_NODES,
                      note=nodes_note),
            Parameter("H", H, "m", "reference thickness", minimum=0.0, open_min=True))


def with_defaults(params: tuple, **defaults) -> tuple:
    """The parameters with some defaults replaced, by name."""
    return tuple(p.with_default(defaults[p.name]) if p.name in defaults else p for p in params)


def law_parameter(name: str, **defaults) -> Parameter:
    """The scene parameter ``name`` as the registered laws declare it: unit and range of the first
    law that takes it (no range if the laws' ranges differ: each law checks its own), doc naming
    each law, default of the first law unless given."""
    declared = [(law, p) for law, (cls, _) in LAWS.items() for p in cls.parameters if p.name == name]
    first = declared[0][1]
    same_range = all((p.minimum, p.maximum, p.open_min, p.open_max)
                     == (first.minimum, first.maximum, first.open_min, first.open_max) for _, p in declared)
    doc = "; ".join(f"{law}: {p.doc}" for law, p in declared)
    bounds = {} if same_range else {"minimum": None, "maximum": None, "open_min": False, "open_max": False}
    return Parameter(**{**first.__dict__, "doc": doc, "default": defaults.get(name, first.default), **bounds})


def material_parameters(material="mooney_rivlin", c1=0.4375, c2=0.0625, eps=1.0, mu_unit="Pa",
                        eps_unit="F/m", pressure_unit="Pa", voltage_unit="V") -> tuple:
    """The material and load parameters of a membrane scene.

    ``mu`` is the scene's shear modulus: not set, it is 2 (c1 + c2); set, the chosen law is given
    that modulus (:meth:`~snapmem.model.materials.Law.with_modulus`: Mooney-Rivlin scales c1 and c2
    keeping c1/c2, Yeoh sets c1 = mu/2, laws with a parameter ``mu`` take it).
    """
    constants = tuple(law_parameter(name, c1=c1, c2=c2) for name in ("c1", "c2", "c3"))
    return (
        (Parameter("material", material, "", "strain energy law", str),)
        + tuple(Parameter(**{**p.__dict__, "unit": mu_unit}) for p in constants)
        + (Parameter("mu", None, mu_unit, "shear modulus; for Mooney-Rivlin scales c1, c2 keeping c1/c2 "
                     "(default 2 (c1 + c2))", minimum=0.0, open_min=True),
           law_parameter("Jlim"),
           Parameter("E_hat", 0.0, "", "normalised electric load (phi/H) sqrt(eps/mu); or set voltage"),
           Parameter("voltage", None, voltage_unit, "voltage phi across the thickness (instead of E_hat)"),
           Parameter("eps", eps, eps_unit, "permittivity", minimum=0.0, open_min=True),
           Parameter("pressure", 0.0, pressure_unit, "pressure difference inside minus outside"))
        + real_membrane_parameters(voltage_unit)
        + viscous_parameters(mu_unit)
    )


class ListParameter(Parameter):
    """A parameter that takes one positive value or several: a number, a sequence of numbers, or
    text 'a,b,c' (as from ``--set NAME=a,b,c``); its value is a tuple of floats."""

    def check(self, value, parse_text: bool = True):
        if value is None:
            return None
        if isinstance(value, str):
            items = [item for item in value.split(",")] if parse_text else [value]
        elif np.ndim(value) == 0:
            items = [value]
        else:
            items = list(value)
        if not items:
            raise SnapmemError(f"{self.name} = {value!r}: give at least one value")
        one = Parameter(**self.__dict__)
        return tuple(float(one.check(item, parse_text)) for item in items)


def viscous_parameters(mu_unit="Pa") -> tuple:
    """The non-equilibrium networks of a viscoelastic membrane (:mod:`snapmem.model.viscous`)."""
    positive = {"minimum": 0.0, "open_min": True}
    return (ListParameter("viscous_mu", None, mu_unit, "shear moduli of the non-equilibrium (viscous) networks, "
                          "one value or a list 'a,b' (None: elastic)", **positive),
            ListParameter("relaxation_time", None, "s", "relaxation times of the viscous networks, one per "
                          "viscous_mu", **positive),
            ListParameter("viscous_Jlim", None, "", "Gent locks of the viscous networks, one per viscous_mu "
                          "(None: every network neo-Hookean)", **positive),
            Parameter("viscous_limit", "relaxed", "", "the static limit of a viscoelastic law (statics): "
                      "'relaxed' (equilibrium network alone) or 'instantaneous' (all networks, xi = 1)", str,
                      choices=VISCOUS_LIMITS))


def viscous_term(params: dict) -> ViscousNetworks | None:
    """The scene's viscous networks, or None for an elastic membrane (``viscous_mu`` not set)."""
    moduli, times = params.get("viscous_mu"), params.get("relaxation_time")
    if moduli is None and times is None:
        return None
    if moduli is None or times is None or len(moduli) != len(times):
        raise SnapmemError(f"viscous_mu = {moduli!r}, relaxation_time = {times!r}: set both, one relaxation "
                           "time per viscous modulus")
    return ViscousNetworks(moduli, times, params.get("viscous_limit", "relaxed"), params.get("viscous_Jlim"))


def real_membrane_parameters(voltage_unit="V") -> tuple:
    """Prestretch and failure limits of a real dielectric elastomer (issue 15).

    The meridian and ``H`` are the mounted (prestretched) ones; the law is evaluated at the total
    stretch relative to the stress-free state (:class:`~snapmem.model.prestretch.Prestretched`).
    The failure limits are checked by :mod:`snapmem.model.local_checks` (None: not checked).
    """
    positive = {"minimum": 0.0, "open_min": True}
    mount = {"minimum": 1.0, "note": _compressed_mount}
    return (Parameter("prestretch", 1.0, "", "equibiaxial prestretch of the mounted membrane (1: stress-free; "
                      ">= 1)", **mount),
            Parameter("prestretch_1", None, "", "meridional prestretch (default: prestretch)", **mount),
            Parameter("prestretch_2", None, "", "hoop prestretch (default: prestretch)", **mount),
            Parameter("E_breakdown", None, f"{voltage_unit}/m", "breakdown strength of the stress-free "
                      "material (None: no breakdown check)", **positive),
            Parameter("breakdown_exponent", 0.0, "", "k of E_B = E_breakdown (area stretch)^k, area stretch "
                      "from the stress-free state"),
            Parameter("stretch_limit", None, "", "rupture: largest principal stretch from the stress-free "
                      "state (None: no check)", minimum=1.0, open_min=True))


def _compressed_mount(value) -> str:
    """Why a prestretch below 1 is refused (Parameter.note)."""
    return (" (a prestretch below 1 mounts the membrane compressed in that direction: a membrane has no "
            "bending stiffness, so it would wrinkle at once, which this model does not represent)")


def mounted_law(params: dict, law: Law) -> Law:
    """``law`` evaluated at the total stretch of the mounting's prestretches (itself if they are 1)."""
    lp = params.get("prestretch", 1.0)
    lp1 = params.get("prestretch_1") or lp
    lp2 = params.get("prestretch_2") or lp
    return law if lp1 == 1.0 and lp2 == 1.0 else Prestretched(law, float(lp1), float(lp2))


def scene_law(params: dict) -> Law:
    """The law of resolved membrane parameters: ``material`` itself if it is a Law instance, else
    the registered law of that name made from the parameters it declares, given the scene's
    modulus ``mu`` (default 2 (c1 + c2))."""
    material = params["material"]
    if isinstance(material, Law):
        return material
    cls = law_class(material)
    mu = params["mu"] if params["mu"] is not None else 2.0 * (params["c1"] + params["c2"])
    values = cls.with_modulus({p.name: params[p.name] for p in cls.parameters}, mu)
    return cls.from_parameters(**values)


def _recorded(params: dict, law: Law) -> dict:
    """The parameters a scene records: for a law given as an instance, its name, its declared
    parameters and its modulus."""
    if not isinstance(params["material"], Law):
        return params
    return {**params, "material": law_name(law), **{p.name: getattr(law, p.name) for p in type(law).parameters},
            "mu": law.mu}


def build_membrane(params: dict, with_loads: tuple, meridian: Meridian, fixed, name: str,
                   start_guess=None, probes=None, constraints=()) -> Scene:
    """Assemble a membrane scene from resolved material and load parameters.

    Includes the electric term only when there is a voltage (or it is asked for). ``constraints``:
    callables law -> node term (a constraint held by a multiplier, snapmem.model.constraints)
    appended to the terms.
    """
    H = params["H"]
    law = scene_law(params)
    voltage = _voltage(params, law.mu)
    terms = [Stretching(mounted_law(params, law)), PressureWork()]
    loads = {"pressure": params["pressure"]}
    if voltage != 0.0 or "voltage" in with_loads:
        terms.append(Electric(params["eps"], H))
        loads["voltage"] = voltage
    viscous = viscous_term(params)
    if viscous is not None:
        terms.append(viscous)
    terms.extend(make(law) for make in constraints)
    return Scene(meridian, H, terms, fixed=fixed, loads=loads, name=name, parameters=_recorded(params, law),
                 start_guess=start_guess, probes=probes)


def _voltage(params, mu):
    if params["voltage"] is not None:
        if params["E_hat"] != 0.0:
            raise SnapmemError(f"E_hat = {params['E_hat']:g} and voltage = {params['voltage']:g}: "
                               "set one of them, not both")
        return params["voltage"]
    return params["E_hat"] * params["H"] * np.sqrt(mu / params["eps"])


# ------------------------------------------------------------------------------------------
# the validation scenes
def build_plate(params: dict, with_loads: tuple) -> Scene:
    """The plate clamped at its rim (rim node: r and z fixed; axis node: r), with a Hencky start guess."""
    R, H = params["R"], params["H"]
    meridian = disc(R, params["nodes"])
    n = meridian.nodes
    fixed = [0, 1, 2 * (n - 1)]

    def start_guess(loads):
        """Small-deflection (Hencky) dome: w0 = 0.662 R (p R / (E H))^(1/3), E = 3 mu."""
        scene_mu = 3.0 * scene_law(params).mu
        p = abs(loads.get("pressure", 0.0))
        w0 = 0.662 * R * (p * R / (scene_mu * H)) ** (1.0 / 3.0) if p > 0 else 1e-3 * R
        q = meridian.q.copy()
        q[1::2] = np.sign(loads.get("pressure", 1.0) or 1.0) * w0 * (1.0 - (meridian.r / R) ** 2)
        return q

    return build_membrane(params, with_loads, meridian, fixed, "plate", start_guess=start_guess,
                          probes={"deflection": lambda q: float(q[-1])})


#: The balloon's supports: what removes its rigid translation along the axis.
BALLOON_SUPPORTS = ("pole", "free")


def _balloon(params, with_loads):
    R = params["R"]
    meridian = sphere(R, params["nodes"])
    n = meridian.nodes
    support = params["support"]
    if support not in BALLOON_SUPPORTS:
        raise SnapmemError(f"support = {support!r}: must be one of {', '.join(BALLOON_SUPPORTS)}")
    constraints = ()
    if support == "pole":
        fixed = [0, 1, 2 * (n - 1)]        # south pole: r and z; north pole: r
    else:                                  # poles on the axis; the centre of mass height held
        fixed = [0, 2 * (n - 1)]
        constraints = (lambda law: CentreOfMassHeight(meridian.z, node_areas(meridian), law.mu * params["H"]),)
    return build_membrane(params, with_loads, meridian, fixed, "balloon",
                          probes={"stretch": lambda q: float(q[0: 2 * n: 2].max() / R)}, constraints=constraints)


def _torus(params, with_loads):
    Rb, Rs = params["Rb"], params["Rs"]
    if params["aspect_ratio"] is not None:          # Rs is then not given (its Parameter excludes it)
        Rs = params["Rs"] = params["aspect_ratio"] * Rb
    if Rs >= Rb:
        raise SnapmemError(f"Rs = {Rs:g}: must be < Rb = {Rb:g} (the cross-section may not reach the axis)")
    meridian = torus(Rb, Rs, params["nodes"])
    return build_membrane(params, with_loads, meridian, [1], "torus",
                          probes={"outer_radius": lambda q: float(q[0::2].max())})


# ---------------------------------------------------------------------------------------------
# the balloon on a gas reservoir: ``balloon --set chamber=gas --set gas_volume=...``
GAS_PARAMETERS = (
    Parameter("chamber", "pressure", "", "what inflates the balloon: 'pressure' (prescribed) or 'gas' (a "
              "reservoir of gas_volume holding gas_amount; trace with --control gas_amount), or 'adiabatic' "
              "(the same gas compressed adiabatically, P V^gamma = gas_amount)", str,
              choices=("pressure", "gas", "adiabatic")),
    Parameter("gamma", 1.4, "", "adiabatic exponent c_p / c_v (chamber = adiabatic)", minimum=1.0),
    Parameter("gas_volume", 0.0, "m^3", "the gas reservoir's (and tubing's) volume besides the balloon "
              "(chamber = gas)", minimum=0.0),
    Parameter("p_atm", 0.25, "Pa", "ambient absolute pressure (chamber = gas; 0.25 mu ~ 1 bar for mu = 0.42 MPa)",
              minimum=0.0, open_min=True),
    Parameter("gas_amount", None, "J", "n R T of the gas when it is not the control (chamber = gas; default: "
              "p_atm times the reference balloon's and reservoir's volume; adiabatic: P V^gamma [Pa m^(3 gamma)])",
              minimum=0.0, open_min=True))
_GAS_NAMES = tuple(p.name for p in GAS_PARAMETERS)


def _with_gas_chamber(pressure_builder):
    """The balloon's builder taking ``chamber``: ``pressure`` builds as before (the chamber's
    parameters dropped, so the recorded parameters are unchanged); ``gas`` puts the balloon on a
    gas chamber of dead volume ``gas_volume`` (one membrane of a MultiScene)."""

    def build(params: dict, with_loads: tuple):
        own = {k: v for k, v in params.items() if k not in _GAS_NAMES}
        if params["chamber"] == "pressure":
            return pressure_builder(own, with_loads)
        if params["pressure"] != 0.0:
            raise SnapmemError(f"pressure = {params['pressure']:g} with chamber = {params['chamber']}: "
                               "the gas sets the pressure "
                               "(set gas_amount, or trace with --control gas_amount)")
        balloon = pressure_builder(own, with_loads)
        chamber = Chamber(ChamberKind(params["chamber"]), (0,), dead_volume=params["gas_volume"],
                          p_atm=params["p_atm"], amount=params["gas_amount"], gamma=params["gamma"])
        recorded = {**balloon.parameters, **{k: params[k] for k in _GAS_NAMES}}
        return MultiScene([balloon], [chamber], name="balloon", parameters=recorded)

    return build


register(SceneSpec(
    "plate", "circular plate clamped at its rim, inflated from one side (paper Fig. 3d)",
    common_parameters(101, H=0.5)
    + (Parameter("R", 7.5, "m", "plate radius", minimum=0.0, open_min=True),)
    + material_parameters(c1=0.4, c2=0.1),
    build_plate))

register(SceneSpec(
    "balloon", "spherical balloon, poles on the axis (paper Figs 3e, 4); or inflated from a gas reservoir "
    "(chamber = gas)",
    common_parameters(101, H=0.1)
    + (Parameter("R", 10.0, "m", "sphere radius", minimum=0.0, open_min=True),
       Parameter("support", "pole", "", "what removes the rigid translation: 'pole' (the south pole's z "
                 "held) or 'free' (the centre of mass height held by a multiplier; keeps the up-down "
                 "symmetry)", str))
    + material_parameters() + GAS_PARAMETERS,
    _with_gas_chamber(_balloon)))

register(SceneSpec(
    "torus", "toroidal membrane, circle of radius Rs about (Rb, 0) (paper Figs 3f, 5)",
    common_parameters(100, H=0.1)
    + (Parameter("Rb", 10.0, "m", "axis to the centre of the cross-section", minimum=0.0, open_min=True),
       Parameter("Rs", 2.0, "m", "cross-section radius (< Rb)", minimum=0.0, open_min=True),
       Parameter("aspect_ratio", None, "", "Rs / Rb instead of Rs: Rs = aspect_ratio * Rb", minimum=0.0,
                 maximum=1.0, open_min=True, open_max=True, excludes=("Rs",)))
    + material_parameters(),
    _torus))
