import os

# The suite tests the compiled kernels: with an empty numba cache (a fresh clone) they would run as
# Python at first (snapmem._lazy's first-use policy; tests/test_startup_cold.py tests that policy
# in its own processes), and a detached compile would start when the suite exits.
os.environ.setdefault("SNAPMEM_COLD", "compile")
os.environ.setdefault("SNAPMEM_BACKGROUND_COMPILE", "0")

import numpy as np
import pytest

import snapmem
from snapmem.model.meridian import disc, sphere, torus


def perturbed(meridian, fixed, rng, scale=0.05, stretch=1.3):
    """A random state near a uniformly stretched reference, fixed dofs at their reference values."""
    q0 = meridian.q
    q = q0 * stretch + rng.normal(scale=scale * meridian.size / meridian.nodes ** 0.5, size=q0.size)
    q[fixed] = q0[fixed]
    return q


# the three reference shapes with their boundary conditions (closed meridian included)
SHAPES = {
    "disc": (lambda: disc(7.5, 11), lambda n: [0, 1, 2 * (n - 1)]),
    "sphere": (lambda: sphere(10.0, 11), lambda n: [0, 1, 2 * (n - 1)]),
    "torus": (lambda: torus(10.0, 2.0, 12), lambda n: [1]),
}


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture
def reference_path():
    """Run the test on the numpy reference path (``snapmem.reference_path()``): no optional compiled kernel."""
    with snapmem.reference_path():
        yield
