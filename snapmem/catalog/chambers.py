"""Scenes of several membranes sharing chambers: ``two_balloons``.

``two_balloons`` is the classic two-balloon experiment: two Mooney-Rivlin balloons (the
validation balloon of MODEL.md section 6 by default, radii ``R1`` and ``R2``) joined by a tube,
so that they share one chamber. The chamber holds an incompressible fluid of prescribed volume
(``chamber = volume``: trace it with ``--control volume``, the total volume of the two balloons)
or an isothermal ideal gas (``chamber = gas``) or an adiabatic one (``chamber = adiabatic``, exponent
``gamma``) (the ``gas_amount`` control: n R T [J], or P V^gamma adiabatic, with
the tube's and reservoir's ``dead_volume`` and the ambient ``p_atm``). The symmetric branch of an
identical pair loses stability where one balloon's dp/dV = 0 (a BP), and the smaller balloon
empties into the larger along the asymmetric branch that bifurcates there.

Its continuation aims at 5 corrector iterations a step, not 3, and gives a diverging corrector up
at once (:data:`TWO_BALLOONS_CONTINUATION`, the scene's ``continuation_defaults``;
``ContinuationOptions(target_iterations=..., abandon_diverging=...)`` overrides them): about half
the points, a fifth fewer corrector iterations on the asymmetric branch's sharp fold, and the BPs,
the fold and the end point located are the generic options' to 1e-11 relative
(tests/test_chambers.py), since a located point does not depend on the steps around it.

The balloon on a gas reservoir (``balloon --set chamber=gas``) is the ``balloon`` scene itself
(snapmem.catalog.membranes).
"""

from __future__ import annotations

from snapmem.catalog.membranes import build_membrane, common_parameters, material_parameters
from snapmem.catalog.registry import Parameter, SceneSpec, register
from snapmem.model.chambers import Chamber, ChamberKind
from snapmem.model.meridian import sphere
from snapmem.model.multi import MultiScene


def balloon_membrane(params: dict, with_loads: tuple, R: float, name: str):
    """One balloon of radius R [m] (south pole: r and z held; north pole: r), with its ``stretch``
    probe (equatorial radius / R)."""
    meridian = sphere(R, params["nodes"])
    n = meridian.nodes
    return build_membrane({**params, "pressure": 0.0}, with_loads, meridian, [0, 1, 2 * (n - 1)], name,
                          probes={"stretch": lambda q: float(q[0::2].max() / R)})


#: The continuation options ``two_balloons`` takes where the caller leaves them unset (module docstring).
TWO_BALLOONS_CONTINUATION = {"target_iterations": 5, "abandon_diverging": True}


def _two_balloons(params: dict, with_loads: tuple) -> MultiScene:
    first = balloon_membrane(params, with_loads, params["R1"], "balloon_1")
    second = balloon_membrane(params, with_loads, params["R2"], "balloon_2")
    kind = ChamberKind(params["chamber"])
    chamber = Chamber(kind, (0, 1), pressure=0.0, dead_volume=params["dead_volume"], p_atm=params["p_atm"],
                      amount=params["gas_amount"], gamma=params["gamma"])
    recorded = {**first.parameters, "pressure": 0.0}          # the law as recorded (a law instance by its name)
    return MultiScene([first, second], [chamber], name="two_balloons", parameters=recorded,
                      continuation_defaults=TWO_BALLOONS_CONTINUATION)


register(SceneSpec(
    "two_balloons", "two balloons sharing one chamber (fluid volume or gas), the two-balloon experiment "
    "(continuation by default: 5 corrector iterations aimed at, a diverging corrector given up at once)",
    common_parameters(101, H=0.1)
    + (Parameter("R1", 10.0, "m", "first balloon's radius", minimum=0.0, open_min=True),
       Parameter("R2", 10.0, "m", "second balloon's radius", minimum=0.0, open_min=True),
       Parameter("chamber", "volume", "", "what fills the shared chamber: an incompressible fluid, an "
                 "isothermal gas or an adiabatic one", str, choices=("volume", "gas", "adiabatic")),
       Parameter("gamma", 1.4, "", "adiabatic exponent c_p / c_v (chamber = adiabatic)", minimum=1.0),
       Parameter("dead_volume", 0.0, "m^3", "tube and reservoir volume (gas chamber)", minimum=0.0),
       Parameter("p_atm", 0.25, "Pa", "ambient absolute pressure (gas chamber; 0.25 mu ~ 1 bar for "
                 "mu = 0.42 MPa)", minimum=0.0, open_min=True),
       Parameter("gas_amount", None, "J", "n R T of the gas when it is not the control (default: "
                 "p_atm times the reference chamber volume; adiabatic: P V^gamma [Pa m^(3 gamma)])",
                 minimum=0.0, open_min=True))
    + tuple(p for p in material_parameters() if p.name != "pressure"),
    _two_balloons))
