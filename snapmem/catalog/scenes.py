"""Named scenes with documented parameters: what ``snapmem scenes`` lists and the CLI builds.

A scene is registered once with its parameters (name, default, unit, allowed range, doc) and a
builder that turns validated parameters into a :class:`~snapmem.model.scene.Scene`. The defaults of
``plate``, ``balloon`` and ``torus`` are the paper's validation cases (MODEL.md section 6), in
normalised units (mu = 1, so pressures are p_hat and stresses are in units of mu).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from snapmem.errors import SnapmemError, check_int, check_real
from snapmem.model.materials import LAWS, make_law
from snapmem.model.meridian import Meridian, disc, sphere, torus
from snapmem.model.scene import Scene
from snapmem.model.terms import Electric, PressureWork, Stretching


@dataclass(frozen=True)
class Parameter:
    """One scene parameter.

    Attributes
    ----------
    name, unit, doc : str
    default : float, int, str or None
        None means "not set" (derived from other parameters).
    kind : type
        float, int or str.
    minimum, maximum : float, optional
        Allowed range (``open_min``/``open_max`` exclude the bound itself).
    choices : tuple of str, optional
        Allowed values of a string parameter.
    """

    name: str
    default: object
    unit: str
    doc: str
    kind: type = float
    minimum: float | None = None
    maximum: float | None = None
    open_min: bool = False
    open_max: bool = False
    choices: tuple = ()

    def check(self, value):
        """The value converted to ``kind``, or SnapmemError naming this parameter."""
        if value is None:
            return None
        if self.kind is str:
            if not isinstance(value, str) or (self.choices and value not in self.choices):
                raise SnapmemError(f"{self.name} = {value!r}: must be one of {', '.join(self.choices)}")
            return value
        if isinstance(value, str):
            value = _parse_number(self.name, value)
        if self.kind is int:
            return check_int(self.name, value, minimum=self.minimum, maximum=self.maximum)
        return check_real(self.name, value, minimum=self.minimum, maximum=self.maximum,
                          min_inclusive=not self.open_min, max_inclusive=not self.open_max)


def _parse_number(name, text):
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        raise SnapmemError(f"{name} = {text!r}: must be a number") from None


@dataclass(frozen=True)
class SceneSpec:
    """A named scene: its parameters and the builder that makes a Scene from them."""

    name: str
    doc: str
    parameters: tuple
    builder: Callable[..., Scene]

    def resolve(self, **values) -> dict:
        """Defaults updated by ``values``, each checked; unknown names are an error."""
        known = {p.name: p for p in self.parameters}
        for key in values:
            if key not in known:
                raise SnapmemError(f"parameter {key!r}: scene {self.name!r} has no such parameter; "
                                   f"it has {', '.join(known)}")
        return {name: p.check(values.get(name, p.default)) for name, p in known.items()}

    def build(self, with_loads: tuple = (), **values) -> Scene:
        """Build the scene. ``with_loads`` names loads (e.g. 'voltage') whose terms are included
        even when their value is zero (for continuation in that load)."""
        params = self.resolve(**values)
        return self.builder(params, tuple(with_loads))


SCENES: dict[str, SceneSpec] = {}


def register(spec: SceneSpec) -> SceneSpec:
    """Add a scene to the registry (the one place a new scene is made known)."""
    SCENES[spec.name] = spec
    return spec


def get_spec(name: str) -> SceneSpec:
    if name not in SCENES:
        raise SnapmemError(f"scene {name!r}: unknown; available: {', '.join(SCENES)}")
    return SCENES[name]


def build_scene(name: str, with_loads: tuple = (), **params) -> Scene:
    """Build the registered scene ``name`` with parameters overriding its defaults.

    Examples
    --------
    >>> scene = build_scene("balloon", nodes=101, E_hat=0.1538)
    """
    return get_spec(name).build(with_loads, **params)


# ------------------------------------------------------------------------------------------
# parameters shared by the membrane scenes
def material_parameters(material="mooney_rivlin", c1=0.4375, c2=0.0625, eps=1.0, mu_unit="Pa",
                        eps_unit="F/m", pressure_unit="Pa", voltage_unit="V"):
    return (
        Parameter("material", material, "", "strain energy law", str, choices=tuple(LAWS)),
        Parameter("c1", c1, mu_unit, "Mooney-Rivlin / Yeoh constant c1", minimum=0.0, open_min=True),
        Parameter("c2", c2, mu_unit, "Mooney-Rivlin constant c2 (Yeoh: c2 of (I1-3)^2)"),
        Parameter("c3", 0.0, mu_unit, "Yeoh constant of (I1-3)^3"),
        Parameter("mu", None, mu_unit, "shear modulus; for Mooney-Rivlin scales c1, c2 keeping c1/c2 "
                  "(default 2 (c1 + c2))", minimum=0.0, open_min=True),
        Parameter("Jlim", 270.0, "", "Gent limit of I1 - 3", minimum=0.0, open_min=True),
        Parameter("E_hat", 0.0, "", "normalised electric load (phi/H) sqrt(eps/mu); or set voltage"),
        Parameter("voltage", None, voltage_unit, "voltage phi across the thickness (instead of E_hat)"),
        Parameter("eps", eps, eps_unit, "permittivity", minimum=0.0, open_min=True),
        Parameter("pressure", 0.0, pressure_unit, "pressure difference inside minus outside"),
    )


def build_membrane(params: dict, with_loads: tuple, meridian: Meridian, fixed, name: str,
                   start_guess=None, probes=None) -> Scene:
    """Assemble a membrane scene from resolved material and load parameters.

    Includes the electric term only when there is a voltage (or it is asked for).
    """
    H = params["H"]
    law = _law(params)
    voltage = _voltage(params, law.mu)
    terms = [Stretching(law), PressureWork()]
    if voltage != 0.0 or "voltage" in with_loads:
        terms.append(Electric(params["eps"], H))
    loads = {"pressure": params["pressure"]}
    if len(terms) == 3:
        loads["voltage"] = voltage
    return Scene(meridian, H, terms, fixed=fixed, loads=loads, name=name, parameters=params,
                 start_guess=start_guess, probes=probes)


def _law(params):
    material, mu = params["material"], params["mu"]
    if material == "mooney_rivlin":
        c1, c2 = params["c1"], params["c2"]
        if mu is not None:
            c1, c2 = mu * c1 / (2 * (c1 + c2)), mu * c2 / (2 * (c1 + c2))
        return make_law(material, c1=c1, c2=c2)
    if mu is None:
        mu = 2.0 * (params["c1"] + params["c2"])
    if material == "yeoh":
        return make_law(material, c1=0.5 * mu, c2=params["c2"], c3=params["c3"])
    return make_law(material, mu=mu, Jlim=params["Jlim"])


def _voltage(params, mu):
    if params["voltage"] is not None:
        if params["E_hat"] != 0.0:
            raise SnapmemError(f"E_hat = {params['E_hat']:g} and voltage = {params['voltage']:g}: "
                               "set one of them, not both")
        return params["voltage"]
    return params["E_hat"] * params["H"] * np.sqrt(mu / params["eps"])


# ------------------------------------------------------------------------------------------
# the validation scenes
def _plate(params, with_loads):
    R, H = params["R"], params["H"]
    meridian = disc(R, params["nodes"])
    n = meridian.nodes
    fixed = [0, 1, 2 * (n - 1)]            # rim node: r and z; axis node: r

    def start_guess(loads):
        """Small-deflection (Hencky) dome: w0 = 0.662 R (p R / (E H))^(1/3), E = 3 mu."""
        scene_mu = 3.0 * _law(params).mu
        p = abs(loads.get("pressure", 0.0))
        w0 = 0.662 * R * (p * R / (scene_mu * H)) ** (1.0 / 3.0) if p > 0 else 1e-3 * R
        q = meridian.q.copy()
        q[1::2] = np.sign(loads.get("pressure", 1.0) or 1.0) * w0 * (1.0 - (meridian.r / R) ** 2)
        return q

    return build_membrane(params, with_loads, meridian, fixed, "plate", start_guess=start_guess,
                          probes={"deflection": lambda q: float(q[-1])})


def _balloon(params, with_loads):
    R = params["R"]
    meridian = sphere(R, params["nodes"])
    n = meridian.nodes
    fixed = [0, 1, 2 * (n - 1)]            # south pole: r and z; north pole: r
    return build_membrane(params, with_loads, meridian, fixed, "balloon",
                          probes={"stretch": lambda q: float(q[0::2].max() / R)})


def _torus(params, with_loads):
    Rb, Rs = params["Rb"], params["Rs"]
    if params["aspect_ratio"] is not None:
        Rs = params["Rs"] = params["aspect_ratio"] * Rb
    if Rs >= Rb:
        raise SnapmemError(f"Rs = {Rs:g}: must be < Rb = {Rb:g} (the cross-section may not reach the axis)")
    meridian = torus(Rb, Rs, params["nodes"])
    return build_membrane(params, with_loads, meridian, [1], "torus",
                          probes={"outer_radius": lambda q: float(q[0::2].max())})


def _common(nodes):
    return (Parameter("nodes", nodes, "", "number of meridian nodes", int, minimum=3),
            Parameter("H", None, "m", "reference thickness", minimum=0.0, open_min=True))


def _with_default(params, **defaults):
    return tuple(Parameter(**{**p.__dict__, "default": defaults[p.name]}) if p.name in defaults else p
                 for p in params)


register(SceneSpec(
    "plate", "circular plate clamped at its rim, inflated from one side (paper Fig. 3d)",
    _with_default(_common(101), H=0.5)
    + (Parameter("R", 7.5, "m", "plate radius", minimum=0.0, open_min=True),)
    + material_parameters(c1=0.4, c2=0.1),
    _plate))

register(SceneSpec(
    "balloon", "spherical balloon, poles on the axis (paper Figs 3e, 4)",
    _with_default(_common(101), H=0.1)
    + (Parameter("R", 10.0, "m", "sphere radius", minimum=0.0, open_min=True),)
    + material_parameters(),
    _balloon))

register(SceneSpec(
    "torus", "toroidal membrane, circle of radius Rs about (Rb, 0) (paper Figs 3f, 5)",
    _with_default(_common(100), H=0.1)
    + (Parameter("Rb", 10.0, "m", "axis to the centre of the cross-section", minimum=0.0, open_min=True),
       Parameter("Rs", 2.0, "m", "cross-section radius (< Rb)", minimum=0.0, open_min=True),
       Parameter("aspect_ratio", None, "", "Rs / Rb; if set, Rs = aspect_ratio * Rb", minimum=0.0,
                 maximum=1.0, open_min=True, open_max=True))
    + material_parameters(),
    _torus))


import snapmem.catalog.robots as robots  # noqa: E402,F401  (registers the robotic scenes: pump, grippers, ball, torus_snap)
