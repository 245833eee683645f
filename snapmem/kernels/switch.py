"""The one switch between the compiled path and the numpy reference path.

Wherever the package can compute a thing either by a compiled kernel or by the numpy
expressions it fuses (the edge kinematics, a law's chain rule, the scene's membrane assembly,
the compiled time step), it asks :func:`compiled` which to take. The default is compiled;
inside ``with reference_path():`` every such choice takes the reference (the tests compare the
two this way)::

    import snapmem
    with snapmem.reference_path():
        slow = scene.evaluate(q)

The switch is process-wide (not per thread) and nests.
"""

from __future__ import annotations

from contextlib import contextmanager

_depth = 0          # how many reference_path() blocks are open


def compiled() -> bool:
    """Whether to take the compiled path (False inside :func:`reference_path`)."""
    return _depth == 0


@contextmanager
def reference_path():
    """Run the enclosed block on the numpy reference path (no compiled kernel where one is optional)."""
    global _depth
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
