"""Tutorial 6: your own scene.

A scene is a meridian (the membrane's generating curve, nodes (r, z)), a list of energy terms
(stretching with a law, pressure work, electric energy, contacts), the fixed degrees of freedom
and the loads. A :class:`snapmem.SceneSpec` gives it a name and declared parameters (defaults,
units, ranges), and :func:`snapmem.catalog.registry.register` makes every command take it
(``snapmem scenes`` lists it, ``--set`` checks its parameters).

Here a neo-Hookean balloon of its own, on a sphere of radius R; its equilibrium under pressure is
checked against the exact neo-Hookean thin sphere, p = (2 H mu / R)(1/lam - 1/lam^7), whose limit
point is at lam = 7^(1/6).

    python docs/tutorials/t6_own_scene.py [--quick]
"""

from snapmem import NeoHookean, Parameter, PressureWork, Scene, SceneSpec, Stretching, build_scene, equilibrium, sphere
from snapmem.catalog.registry import SCENES, register

from _common import parse


def build_neo_balloon(params: dict, with_loads: tuple) -> Scene:
    """The balloon: south pole fixed in r and z, north pole on the axis (r fixed)."""
    meridian = sphere(params["R"], params["nodes"])
    n = meridian.nodes
    return Scene(meridian, params["H"], [Stretching(NeoHookean(params["mu"])), PressureWork()],
                 fixed=[0, 1, 2 * (n - 1)], loads={"pressure": params["pressure"]}, name="neo_balloon",
                 parameters=params)


SPEC = SceneSpec(
    "neo_balloon", "neo-Hookean spherical balloon (tutorial 6)",
    (Parameter("nodes", 101, "", "number of meridian nodes", int, minimum=3),
     Parameter("R", 10.0, "m", "sphere radius", minimum=0.0, open_min=True),
     Parameter("H", 0.1, "m", "reference thickness", minimum=0.0, open_min=True),
     Parameter("mu", 1.0, "Pa", "shear modulus", minimum=0.0, open_min=True),
     Parameter("pressure", 0.0, "Pa", "pressure inside minus outside")),
    build_neo_balloon)
if "neo_balloon" not in SCENES:
    register(SPEC)


def exact_pressure(lam, R=10.0, H=0.1, mu=1.0):
    """Pressure [Pa] of the neo-Hookean thin sphere at stretch lam."""
    return 2.0 * H * mu / R * (1.0 / lam - 1.0 / lam ** 7)


def main(argv=None):
    args = parse(__doc__, argv)
    lam = 1.2                                        # below the limit stretch 7^(1/6) = 1.383: stable
    scene = build_scene("neo_balloon", nodes=41 if args.quick else 201, pressure=exact_pressure(lam))
    eq = equilibrium(scene)
    r = eq.q[0::2]
    stretch = r.max() / 10.0
    print(f"neo_balloon at p = {exact_pressure(lam):.6g} Pa: equator stretch {stretch:.6g} (exact {lam}), "
          f"{eq.report.status}")
    return stretch, lam


if __name__ == "__main__":
    main()
