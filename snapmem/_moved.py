"""Old module paths, kept working after the package was split into layers.

Each entry maps a module path that scripts outside this repository may import (the flat layout of
snapmem 0.1) to where the module lives now. Importing the old path gives the very same module
object, so attribute reads, ``monkeypatch`` and ``isinstance`` checks behave as before. Code
inside ``snapmem/`` always imports the new paths (a test checks this).
"""

from __future__ import annotations

import importlib
import importlib.machinery
import sys

MOVED = {
    "banded": "kernels.banded",
    "bordered": "kernels.bordered",
    "contact_kernels": "kernels.contact",
    "meridian": "model.meridian",
    "materials": "model.materials",
    "kinematics": "model.kinematics",
    "terms": "model.terms",
    "contact": "model.contact",
    "scene": "model.scene",
    "newton": "solvers.newton",
    "hysteresis": "continuation.hysteresis",
    "compiled_step": "dynamics.compiled_step",
    "scenes": "catalog.scenes",
    "robots": "catalog.robots",
    "exact": "reference.exact",
    "membrane_ode": "reference.membrane_ode",
    "paths": "reference.paths",
    "plotting": "viz.plotting",
    "replay": "viz.replay",
    "results": "io.results",
    "sweep": "sweeps.sweep",
    "stress": "stress_cases",
}


class _Alias:
    """A loader (the import system's protocol; importlib.abc's base class costs 13 ms of start-up)."""

    def __init__(self, target: str):
        self.target = target

    def create_module(self, spec):
        return importlib.import_module(self.target)

    def exec_module(self, module):
        pass


class _MovedFinder:
    """Finds ``snapmem.<old>`` and answers with the module now at ``snapmem.<new>``."""

    def find_spec(self, fullname, path=None, target=None):
        prefix, _, name = fullname.partition(".")
        if prefix != "snapmem" or name not in MOVED:
            return None
        return importlib.machinery.ModuleSpec(fullname, _Alias("snapmem." + MOVED[name]))


def install() -> None:
    if not any(isinstance(f, _MovedFinder) for f in sys.meta_path):
        sys.meta_path.append(_MovedFinder())

