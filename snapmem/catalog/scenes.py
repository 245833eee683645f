"""Named scenes with documented parameters: what ``snapmem scenes`` lists and the CLI builds.

Importing this module registers every scene of the catalog: the validation scenes
(snapmem.catalog.membranes) and the robotic ones (snapmem.catalog.robot_scenes). The registry
itself is snapmem.catalog.registry; its names are re-exported here, where they have always been
(``snapmem.scenes`` is this module).
"""

from snapmem.catalog.registry import SCENES, Parameter, SceneSpec, build_scene, get_spec, register
from snapmem.catalog.membranes import build_membrane, material_parameters
import snapmem.catalog.robot_scenes  # noqa: F401  (registers pump, the grippers, the ball scenes, torus_snap)

__all__ = ["SCENES", "Parameter", "SceneSpec", "build_scene", "get_spec", "register", "build_membrane",
           "material_parameters"]
import snapmem.catalog.chambers  # noqa: F401  (registers two_balloons)
import snapmem.catalog.pump2  # noqa: F401  (registers pump2)
