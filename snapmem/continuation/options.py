"""Options of continuation: what :func:`~snapmem.continuation.tracer.trace` and
:func:`~snapmem.continuation.folds.fold_curve` take, with their defaults and checks."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from snapmem.errors import SnapmemError, check_int, check_real

#: The parameters a branch can be traced in.
CONTROLS = ("pressure", "voltage", "E_hat", "volume", "gas_amount")   # gas_amount: a gas chamber's n R T [J]


@dataclass(frozen=True)
class ContinuationOptions:
    """Options of :func:`snapmem.continuation.tracer.trace`, with their defaults.

    Attributes
    ----------
    ds : float
        First step length (scaled arclength, dimensionless), default 0.05.
    ds_min, ds_max : float
        Step bounds, default 1e-6 and 0.3.
    max_steps : int
        Accepted steps at most, default 2000.
    newton_tol : float
        Corrector tolerance on max |R| relative to the scene's force scale, default 1e-10.
    max_corrector_iterations : int
        Default 8; more means the step is cut.
    target_iterations : int or None
        Corrector iterations aimed at; fewer grow the step, more shrink it. Default None: the
        scene's own (its ``continuation_defaults``, listed by ``snapmem scenes``), else
        3 (:data:`SCENE_DEFAULTS`, :func:`resolve_options`).
    max_angle : float
        Largest angle between consecutive tangents [rad] before a step is cut, default 0.3.
    abandon_diverging : bool or None
        Give a step's corrector up at the first Newton iterate whose max |R| exceeds the
        predictor's (and 1e3 times the tolerance): it is diverging, and the step is cut at once
        instead of after ``max_corrector_iterations`` (the trace's steps only: locating a point and
        a switch's first step run their correctors to the limit).
        Default None: the scene's, else False.
    n_eigs : int
        Eigenvalues nearest zero watched at every point, default 2 (the negative count comes
        from an LDL^T factorisation, not from these).
    stability : bool
        Compute eigenvalues and inertia at every point (default True).
    locate : bool
        Locate critical points precisely (default True).
    stop_at_first_limit : bool
        Stop the trace at the first limit point (default False).
    save_at : tuple of float
        Values of the control parameter at which points are located exactly (not interpolated).
    direction : int
        +1 to start with the parameter increasing, -1 decreasing.
    """

    ds: float = 0.05
    ds_min: float = 1e-6
    ds_max: float = 0.3
    max_steps: int = 2000
    newton_tol: float = 1e-10
    max_corrector_iterations: int = 8
    target_iterations: int | None = None
    max_angle: float = 0.3
    abandon_diverging: bool | None = None
    n_eigs: int = 2
    stability: bool = True
    locate: bool = True
    stop_at_first_limit: bool = False
    save_at: tuple = ()
    direction: int = 1

    def __post_init__(self):
        check_real("ds", self.ds, minimum=0.0, min_inclusive=False)
        check_real("ds_min", self.ds_min, minimum=0.0, min_inclusive=False)
        check_real("ds_max", self.ds_max, minimum=self.ds_min)
        check_int("max_steps", self.max_steps, minimum=1)
        check_real("newton_tol", self.newton_tol, minimum=0.0, min_inclusive=False)
        check_int("max_corrector_iterations", self.max_corrector_iterations, minimum=1)
        if self.target_iterations is not None:
            check_int("target_iterations", self.target_iterations, minimum=1)
        check_real("max_angle", self.max_angle, minimum=0.0, min_inclusive=False, maximum=math.pi)
        check_int("n_eigs", self.n_eigs, minimum=1)
        if self.direction not in (1, -1):
            raise SnapmemError(f"direction = {self.direction!r}: must be +1 or -1")
        object.__setattr__(self, "save_at", tuple(check_real("save_at", v) for v in self.save_at))


#: The options a scene may set for itself (its ``continuation_defaults``, e.g. ``two_balloons``':
#: snapmem.catalog.chambers) where the caller leaves them None, with their values for a scene
#: that does not.
SCENE_DEFAULTS = {"target_iterations": 3, "abandon_diverging": False}

#: Corrector iterations aimed at where neither the options nor the scene say otherwise.
TARGET_ITERATIONS = SCENE_DEFAULTS["target_iterations"]


def resolve_options(options: ContinuationOptions, scene) -> ContinuationOptions:
    """``options`` with each of :data:`SCENE_DEFAULTS` left None set: to the scene's
    ``continuation_defaults`` entry if it has one (a scene whose located points are proven not to
    depend on them), else to the generic value. An option the caller set is kept."""
    unset = [name for name in SCENE_DEFAULTS if getattr(options, name) is None]
    if not unset:
        return options
    own = getattr(scene, "continuation_defaults", None) or {}          # a MultiScene's (Scene has none)
    return replace(options, **{name: own.get(name, SCENE_DEFAULTS[name]) for name in unset})


def resolved_target_iterations(options: ContinuationOptions, scene) -> int:
    """The corrector iterations a trace of ``scene`` with ``options`` aims at (:func:`resolve_options`)."""
    return resolve_options(options, scene).target_iterations


@dataclass(frozen=True)
class FoldOptions:
    """Options of :func:`snapmem.continuation.folds.fold_curve`.

    Attributes
    ----------
    tol : float
        Newton tolerance on max |R| relative to the force scale, default 1e-10.
    max_iterations : int
        Newton iterations per value, default 15.
    max_refinements : int
        Times a failed increment of the second parameter is halved, default 6.
    trace_until : mapping
        Where the first trace (and a fallback trace) gives up looking for a limit point,
        default stretch_max = 12.
    """

    tol: float = 1e-10
    max_iterations: int = 15
    max_refinements: int = 6
    trace_until: tuple = (("stretch_max", 12.0),)

