"""Layer 4: implicit dynamics: time-stepping schemes, the stepper, the compiled time step and settling.

Modules: :mod:`~snapmem.dynamics.schemes` (midpoint, BDF2, Euler as objects),
:mod:`~snapmem.dynamics.loads` (load schedules), :mod:`~snapmem.dynamics.options`
(:class:`DynamicsOptions`), :mod:`~snapmem.dynamics.stepper` (one implicit step, the frame
recorder), :mod:`~snapmem.dynamics.compiled_step` (the compiled time step),
:mod:`~snapmem.dynamics.trajectory` (:class:`Trajectory` and its files),
:mod:`~snapmem.dynamics.driver` (:func:`simulate`) and :mod:`~snapmem.dynamics.settle`
(:func:`settle`: from past a limit point to rest).
"""

from snapmem.dynamics.compiled_step import CompiledStep
from snapmem.dynamics.driver import lumped_masses, simulate
from snapmem.dynamics.loads import PiecewiseLinear, schedule
from snapmem.dynamics.options import DynamicsOptions
from snapmem.dynamics.schemes import SCHEME_BY_NAME, SCHEMES, Anchor, Scheme
from snapmem.dynamics.settle import Settled, settle
from snapmem.dynamics.stepper import EPS
from snapmem.dynamics.trajectory import RunOutcome, Trajectory

__all__ = ["CompiledStep", "DynamicsOptions", "EPS", "PiecewiseLinear", "SCHEMES", "SCHEME_BY_NAME", "Anchor", "Scheme",
           "RunOutcome", "Settled", "Trajectory", "lumped_masses", "schedule", "settle", "simulate"]
