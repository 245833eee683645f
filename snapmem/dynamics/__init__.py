"""Layer 4: implicit dynamics: time-stepping schemes, the stepper, the compiled time step and settling."""

from snapmem.dynamics.driver import *  # noqa: F401,F403
