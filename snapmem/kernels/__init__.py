"""Layer 1: compiled kernels (arrays in, arrays out) and the band linear algebra built on them.

``snapmem.kernels`` re-exports the compiled functions that lived in the old flat module."""

from snapmem.kernels.linalg import *  # noqa: F401,F403
from snapmem.kernels.assembly import *  # noqa: F401,F403
