"""Layer 4: pseudo-arclength continuation of equilibrium branches, their critical points and fold curves."""

from snapmem.continuation.tracer import *  # noqa: F401,F403
