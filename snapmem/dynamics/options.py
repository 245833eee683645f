"""How to integrate in time (:class:`DynamicsOptions`)."""

from __future__ import annotations

from dataclasses import dataclass

from snapmem.dynamics.schemes import SCHEME_BY_NAME, SCHEMES
from snapmem.errors import SnapmemError, check_int, check_real
from snapmem.solvers.newton import NewtonOptions


@dataclass(frozen=True)
class DynamicsOptions:
    """How to integrate in time.

    Attributes
    ----------
    scheme : str
        'midpoint' (second order, symplectic, default), 'bdf2' (second order, L-stable: for
        contact and violent snaps) or 'euler' (first order, the paper's); any name in
        :data:`snapmem.dynamics.schemes.SCHEME_BY_NAME`.
    dt : float
        First (or, with ``adaptive=False``, every) time step [s], default 1e-3.
    adaptive : bool
        Adapt the step to the local error estimate (default True).
    tol : float
        Local error tolerance per step as a fraction of the membrane's size (the larger of the
        reference size L and the current largest coordinate), default 1e-4.
    dt_min, dt_max : float
        Step bounds [s] (defaults 1e-9 and 1.0).
    newton : NewtonOptions
        Tolerances of each step's Newton solve (residual relative to mu H L); defaults tol 1e-9,
        25 iterations and at most 10 step halvings per iteration (statics allow 30): a time step
        whose Newton needs more is cut instead, which is cheaper (docs/performance.md).
    newton_fraction : float
        With ``adaptive``, a step's Newton also ends once the error it leaves (the steps still to
        come at the estimated contraction rate, :func:`snapmem.solvers.rules.increment_error`)
        is at most this fraction of the step's error tolerance ``tol`` L (default 0.1, CVODE's
        choice): the time step's own error is larger, and solving its equations further changes
        nothing it reports. 0: the residual test alone (the tolerance ``newton.tol``), as before
        this option. Several membranes on shared chambers (whose pressures are unknowns of the
        step) keep the residual test alone.
    save_interval : float
        Record a frame at most this often [s] (default 0: every accepted step); the last
        step is always recorded, and ``min_gap`` holds the smallest gap since the previous frame.
    max_steps : int
        Accepted plus rejected steps at most (default 1_000_000).
    line_search : str
        'energy' (default): Newton's step is accepted when it lowers the step's incremental
        potential (Armijo), which is what a time step minimises, and needs fewer step cuts
        (docs/performance.md); 'residual': snapmem.solvers.newton's Armijo on |R|^2.
    """

    scheme: str = "midpoint"
    dt: float = 1e-3
    adaptive: bool = True
    tol: float = 1e-4
    dt_min: float = 1e-9
    dt_max: float = 1.0
    newton: NewtonOptions = NewtonOptions(tol=1e-9, max_iterations=25, max_cuts=10)
    newton_fraction: float = 0.1
    save_interval: float = 0.0
    max_steps: int = 1_000_000
    line_search: str = "energy"

    def __post_init__(self):
        if self.line_search not in ("energy", "residual"):
            raise SnapmemError(f"line_search = {self.line_search!r}: must be 'energy' or 'residual'")
        if self.scheme not in SCHEMES:
            raise SnapmemError(f"scheme = {self.scheme!r}: must be one of {', '.join(SCHEMES)}")
        check_real("dt", self.dt, minimum=0.0, min_inclusive=False)
        check_real("tol", self.tol, minimum=0.0, min_inclusive=False)
        check_real("newton_fraction", self.newton_fraction, minimum=0.0, maximum=1.0)
        check_real("dt_min", self.dt_min, minimum=0.0, min_inclusive=False)
        check_real("dt_max", self.dt_max, minimum=self.dt_min)
        check_real("save_interval", self.save_interval, minimum=0.0)
        check_int("max_steps", self.max_steps, minimum=1)

    @property
    def order(self) -> int:
        """Order of accuracy of the scheme."""
        return SCHEME_BY_NAME[self.scheme].order

