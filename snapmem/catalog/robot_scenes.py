"""The scenes of the paper's soft robots (section 4) and its dynamic torus, registered like the
validation scenes (``snapmem scenes`` lists them). Their time schedules (experiments) are in
snapmem.catalog.robots, which also documents each scene; this module imports no dynamics, so
registering the scenes (``import snapmem``) does not load the time stepper.

SI units; eps = 1e-10 F/m.
"""

from __future__ import annotations

from snapmem.catalog.membranes import build_membrane, build_plate, common_parameters, material_parameters, with_defaults
from snapmem.catalog.registry import Parameter, SceneSpec, register
from snapmem.errors import SnapmemError
from snapmem.model.contact import Ball, Plane, Rod, Shell, contact_report
from snapmem.model.meridian import sphere, torus
from snapmem.model.scene import Scene

EPS = 1e-10                     # permittivity of every robotic scene [F/m]
MU_MR = 4.225e5                 # shear modulus of the gripper and ball membranes [Pa]

ROBOTIC_SCENES = ("pump", "gripper_rod", "gripper_shell", "ball_drop", "ball_throw")


def with_contact(scene: Scene, *contacts) -> Scene:
    """The same scene with contact terms added, and each body's total contact force [N] and
    smallest gap [m] as probes (so continuation tables and measures report them)."""
    out = Scene(scene.meridian, scene.thickness, scene.terms + tuple(contacts), fixed=scene.fixed,
                loads=scene.loads, name=scene.name, parameters=scene.parameters,
                start_guess=scene.start_guess, probes=scene.probes)
    for key in contact_report(out, out.reference_state()):
        out.probes[key] = (lambda k: lambda q: contact_report(out, q)[k])(key)
    return out


def _dynamics_parameters(rho, xi, t_end, tol=1e-3):
    return (Parameter("rho", rho, "kg/m^3", "membrane density", minimum=0.0, open_min=True),
            Parameter("xi", xi, "1/s", "mass-proportional damping", minimum=0.0),
            Parameter("t_end", t_end, "s", "end of the simulation", minimum=0.0, open_min=True),
            Parameter("tol", tol, "", "local time-error tolerance per step, fraction of the size "
                      "(1e-8 to 1: below, steps would shrink past dt_min)", minimum=1e-8, maximum=1.0))


def _contact_parameters(kappa, dhat):
    return (Parameter("kappa", kappa, "Pa", "contact pressure scale of the barrier", minimum=0.0, open_min=True),
            Parameter("dhat", dhat, "m", "barrier width", minimum=0.0, open_min=True))


# ------------------------------------------------------------------------------------------
# pump
def _pump(params, with_loads):
    """The validation plate's scene (rim clamped, Hencky start guess for continuation) named pump."""
    times = [(name, params[name]) for name in ("t_up", "t_hold", "t_down")]
    for (early, t0), (late, t1) in zip(times, times[1:]):
        if t1 < t0:
            raise SnapmemError(f"{late} = {t1:g} s: the pump's schedule needs t_up <= t_hold <= t_down "
                               f"({early} = {t0:g} s)")
    scene = build_plate(params, tuple(with_loads) + ("voltage",))
    scene.name = "pump"
    return scene


register(SceneSpec(
    "pump", "fluid pump: Gent plate at 300 V, pressure cycle 0-30 s (paper Fig. 6)",
    common_parameters(61, H=1e-4)
    + (Parameter("R", 0.1, "m", "plate radius", minimum=0.0, open_min=True),)
    + with_defaults(material_parameters(material="gent", eps=EPS), voltage=300.0, mu=45e3)
    + (Parameter("rate", 10.0, "Pa/s", "pressure rate up and down", minimum=0.0, open_min=True),
       Parameter("t_up", 5.0, "s", "pressure starts rising", minimum=0.0),
       Parameter("t_hold", 15.0, "s", "pressure held and voltage switched off", minimum=0.0),
       Parameter("t_switch", 0.05, "s", "time the voltage takes to fall to 0", minimum=0.0, open_min=True),
       Parameter("t_down", 20.0, "s", "pressure starts falling", minimum=0.0))
    + _dynamics_parameters(1000.0, 1.0, 30.0, tol=2e-2),
    _pump))


# ------------------------------------------------------------------------------------------
# grippers
def _gripper(kind):
    def build(params, with_loads):
        Rb, Rs = params["Rb"], params["Rs"]
        if Rs >= Rb:
            raise SnapmemError(f"Rs = {Rs:g}: must be < Rb = {Rb:g}")
        meridian = torus(Rb, Rs, params["nodes"])
        scene = build_membrane(params, with_loads, meridian, [1], f"gripper_{kind}",
                               probes={"outer_radius": lambda q: float(q[0::2][: meridian.nodes].max()),
                                       "inner_radius": lambda q: float(q[0::2][: meridian.nodes].min())})
        Rw = params["Rw"]
        if kind == "rod":
            if not 0 < Rw < Rb - Rs:
                raise SnapmemError(f"Rw = {Rw:g}: the rod must fit in the hole, 0 < Rw < Rb - Rs = {Rb - Rs:g}")
            body = Rod(kappa=params["kappa"], dhat=params["dhat"], radius=Rw)
        else:
            if Rw <= Rb + Rs:
                raise SnapmemError(f"Rw = {Rw:g}: the shell must lie outside the torus, Rw > Rb + Rs = {Rb + Rs:g}")
            body = Shell(kappa=params["kappa"], dhat=params["dhat"], radius=Rw)
        return with_contact(scene, body)
    return build


for _kind, _rw, _pmax in (("rod", 0.04, 2500.0), ("shell", 0.25, 2500.0)):
    register(SceneSpec(
        f"gripper_{_kind}",
        f"toroidal gripper {'around a rod' if _kind == 'rod' else 'inside a cylindrical shell'} (paper Fig. 7)",
        common_parameters(80, H=1e-4)
        + (Parameter("Rb", 0.1, "m", "axis to the centre of the cross-section", minimum=0.0, open_min=True),
           Parameter("Rs", 0.02, "m", "cross-section radius (< Rb)", minimum=0.0, open_min=True),
           Parameter("Rw", _rw, "m", "rod radius" if _kind == "rod" else "inner radius of the shell",
                     minimum=0.0, open_min=True))
        + with_defaults(material_parameters(eps=EPS), mu=MU_MR)
        + _contact_parameters(1e5, 5e-4)
        + (Parameter("rate", 100.0, "Pa/s", "pressure rate", minimum=0.0, open_min=True),
           Parameter("p_max", _pmax, "Pa", "pressure held after the ramp", minimum=0.0))
        + _dynamics_parameters(1000.0, 1.0, 30.0, tol=1e-2),
        _gripper(_kind)))


# ------------------------------------------------------------------------------------------
# ball actuator
def _ball_scene(params, with_loads):
    R = params["R"]
    meridian = sphere(R, params["nodes"])
    n = meridian.nodes
    scene = build_membrane(params, with_loads, meridian, [0, 1, 2 * (n - 1)], params["name"],
                           probes={"top": lambda q: float(q[2 * n - 1])})
    plate = Plane(kappa=params["kappa"], dhat=params["dhat"], z0=-R, nodes=tuple(range(1, n)))
    ball = Ball(kappa=params["kappa"], dhat=params["dhat"], radius=params["rb"], z0=R + params["rb"] + params["drop"],
                mass=params["mb"], gravity=params["g"], meridian=meridian)      # edges cannot pass through it
    return with_contact(scene, plate, ball)


def _ball_parameters(name, t_end, drop, damp_ball):
    return (common_parameters(61, H=1e-4)
            + (Parameter("R", 0.1, "m", "balloon radius", minimum=0.0, open_min=True),
               Parameter("name", name, "", "scene name", str, choices=("ball_drop", "ball_throw")))
            + with_defaults(material_parameters(eps=EPS), mu=MU_MR, pressure=500.0)
            + _contact_parameters(1e4, 1e-3)
            + (Parameter("rb", 0.05, "m", "ball radius", minimum=0.0, open_min=True),
               Parameter("mb", 0.5, "kg", "ball mass", minimum=0.0, open_min=True),
               Parameter("g", -10.0, "m/s^2", "gravity along z"),
               Parameter("drop", drop, "m", "gap between ball and balloon top at the start", minimum=0.0,
                         open_min=True),
               Parameter("damp_ball", damp_ball, "", "1: damping xi acts on the ball too; 0: it flies freely", int,
                         minimum=0, maximum=1),
               Parameter("rate", 100.0, "Pa/s", "pressure rate (ball_throw)"))
            + _dynamics_parameters(1000.0, 1.0, t_end, tol=4e-3))


register(SceneSpec("ball_drop", "ball dropped on a balloon held at 500 Pa on a plate (paper Fig. 8, case 1)",
                   _ball_parameters("ball_drop", 5.0, 0.05, 1), _ball_scene))
register(SceneSpec("ball_throw", "balloon snaps through under rising pressure and throws the ball (paper Fig. 8, case 2)",
                   _ball_parameters("ball_throw", 2.0, 0.001, 0), _ball_scene))


# ------------------------------------------------------------------------------------------
# torus_snap: the default scene of the paper's C++ code
def _torus_snap(params, with_loads):
    meridian = torus(params["Rb"], params["Rs"], params["nodes"])
    return build_membrane(params, with_loads, meridian, [1], "torus_snap",
                          probes={"outer_radius": lambda q: float(q[0::2][: meridian.nodes].max())})


register(SceneSpec(
    "torus_snap", "the paper's C++ default: torus Rs = 2 about Rb = 10 inflated to 200, snaps through",
    common_parameters(200, H=0.1)
    + (Parameter("Rb", 10.0, "", "axis to the centre of the cross-section", minimum=0.0, open_min=True),
       Parameter("Rs", 2.0, "", "cross-section radius (< Rb)", minimum=0.0, open_min=True))
    + with_defaults(material_parameters(), mu=4225.0)
    + (Parameter("rate", 100.0, "1/s", "pressure rate", minimum=0.0, open_min=True),
       Parameter("p_max", 200.0, "", "pressure held after the ramp", minimum=0.0))
    + _dynamics_parameters(100.0, 1.0, 100.0),
    _torus_snap))
