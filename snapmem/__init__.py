"""snapmem: snap-through of axisymmetric dielectric-elastomer membranes.

A 1D discrete (DDG) model of the membrane's meridian with hyperelastic, electric and pressure
energies, analytic gradients and banded Hessians, and the solvers that use them.

The public API::

    from snapmem import build_scene, equilibrium
    scene = build_scene("balloon", nodes=101, E_hat=0.1538)
    eq = equilibrium(scene, {"pressure": 0.012})
    eq.measures()["stretch"]
"""

from snapmem import _moved

_moved.install()                 # the flat module paths of snapmem 0.1 keep working

from snapmem.errors import SnapmemError, SolverError
from snapmem.kernels.switch import reference_path
from snapmem.model.materials import Gent, Law, InvariantLaw, MooneyRivlin, NeoHookean, Yeoh, LAWS, make_law, register_law
from snapmem.model.meridian import Meridian, disc, sphere, torus
from snapmem.solvers.newton import Equilibrium, NewtonOptions, NewtonReport, solve
from snapmem.statics import equilibrium
from snapmem.model.scene import Scene
from snapmem.catalog.scenes import SCENES, Parameter, SceneSpec, build_scene, register
from snapmem.model.terms import Electric, PressureWork, Stretching
import snapmem.model.contact as contact  # noqa: F401  (registers the contact terms with TERMS)

__all__ = [
    "SnapmemError", "SolverError",
    "Law", "InvariantLaw", "NeoHookean", "MooneyRivlin", "Gent", "Yeoh", "LAWS", "make_law", "register_law",
    "Meridian", "disc", "sphere", "torus",
    "Scene", "Stretching", "Electric", "PressureWork",
    "Equilibrium", "NewtonOptions", "NewtonReport", "equilibrium", "solve",
    "SCENES", "SceneSpec", "Parameter", "build_scene", "register",
    "reference_path",
]
from snapmem._version import __version__  # noqa: E402
