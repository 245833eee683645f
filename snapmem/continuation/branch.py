"""A traced branch: its points, their kinds, why the trace ended, and the branch file."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from enum import Enum

import numpy as np
import snapmem._lazy as _lazy

pd = _lazy.module("pandas")  # imported at first use (start-up)

from snapmem.continuation.problems import make_problem
from snapmem.errors import SnapmemError, read_npz
from snapmem.io.results import write_npz
from snapmem.io.table import FrameField
from snapmem.model.scene import Scene


class PointKind(str, Enum):
    """What a point on a branch is. The values are the words written in the ``kind`` and
    ``point`` columns of tables and branch files."""

    STEP = ""                #: an accepted continuation step
    LP = "LP"                #: a limit point (the null vector couples to dR/dlambda)
    BP = "BP"                #: a bifurcation point
    SAVE = "SAVE"            #: located on a ``save_at`` value
    END = "END"              #: located where the trace stopped (an ``until`` value)
    CRITICAL = "critical"    #: a critical point located but not yet classified
    LE = "LE"                #: loss of ellipticity: the membrane model is ill-posed beyond it (the trace ends)
    LT = "LT"                #: loss of tension: a principal tension falls to zero (wrinkling; the trace goes on)
    EB = "EB"                #: electrical breakdown: ``breakdown_margin`` reaches 1 (the trace goes on)
    RU = "RU"                #: rupture: ``rupture_margin`` reaches 1, the stretch limit (the trace goes on)
    EMI = "EMI"              #: electromechanical instability: the name of an LP in tables under voltage control


class Outcome(str, Enum):
    """Why a trace ended, in one word (:attr:`Branch.status` says it in a sentence)."""

    TARGET_REACHED = "target_reached"      #: an ``until`` value was reached
    FIRST_LIMIT = "first_limit"            #: stopped at the first limit point (``stop_at_first_limit``)
    MAX_STEPS = "max_steps"                #: ``max_steps`` accepted steps
    STEP_TOO_SMALL = "step_too_small"      #: a step was rejected at ``ds_min``
    TENSION_LOST = "tension_lost"          #: a :class:`~snapmem.continuation.events.LossOfTension` event stopped it
    STOPPED = "stopped"                    #: an event passed to ``trace`` stopped it
    ELLIPTICITY_LOST = "ellipticity_lost"  #: the membrane lost strong ellipticity (:class:`~snapmem.continuation.events.LossOfEllipticity`)
    CLOSED = "closed"                      #: the branch came back to a limit point it had passed (:class:`~snapmem.continuation.events.ClosedBranch`)


@dataclass
class Point:
    """One equilibrium on a branch: the state, the control value and what was measured there."""

    x: np.ndarray            # unknowns of the problem (free dofs, + pressure under volume control)
    lam: float               # control parameter
    tangent: np.ndarray | None = None   # unit tangent (x part, lambda part), shape (n + 1,)
    eigs: np.ndarray | None = None
    negative: int | None = None
    s: float = 0.0           # arclength from the start
    ds: float = 0.0          # the step that reached it
    iterations: int = 0      # corrector iterations
    kind: PointKind = PointKind.STEP
    located: bool = False
    coupling: float = float("nan")   # |phi0 . dR/dlambda| / (|phi0| |dR/dlambda|) at a critical point
    crossed: int = -1                # eigenvalues that crossed zero at a critical point
    symmetry_broken: bool = False    # a BP whose null vector couples to the load (the mesh breaks its symmetry)
    mode: int = -1                   # Legendre mode n of a BP's null vector on a spherical reference (-1: none)
    vectors: np.ndarray | None = field(default=None, repr=False)   # eigenvectors of ``eigs``
    subspace: np.ndarray | None = field(default=None, repr=False)  # the eigen-iteration's last subspace
    measured: dict | None = field(default=None, repr=False)        # cache of the problem's measures

    @property
    def test_value(self) -> float:
        return float("nan") if self.eigs is None else float(self.eigs[0])


@dataclass
class Branch:
    """A traced branch: the points table, the critical points and everything to restart from.

    Attributes
    ----------
    table : pandas.DataFrame
        One row per point (accepted steps, located critical points, save_at points), in
        arclength order: pressure, voltage, E_hat, volume, u_max, stretch_max, min_eig,
        negative_eigs, stable, min_tension, taut, point ('' or 'LP' or 'BP'), and the scene's probes.
    points : pandas.DataFrame
        The critical points: ``kind`` and the same quantities at the located point, ``located``
        (False if only bracketed), ``coupling`` (|phi0 . dR/dlambda| normalised), ``crossed``
        (how many eigenvalues crossed zero), ``symmetry_broken`` (a BP whose null vector couples
        to the load above 1e-6: the mesh breaks the symmetry, the bifurcation is imperfect) and
        ``mode`` (the Legendre mode n of a BP's null vector on a spherical reference, else -1).
    rejections : pandas.DataFrame
        Every rejected or cut step: step, s, ds, reason.
    status : str
        Why the trace stopped, in a sentence (e.g. 'stretch reached 4').
    outcome : Outcome
        The same in one word.

    The three tables may be given as :class:`~snapmem.io.table.Rows`: each becomes its DataFrame
    at its first read (pandas is imported then), and ``snapmem.io.table.stored(branch, "table")``
    reads the rows without building it (``snapmem trace`` writes and prints them so).
    """

    scene: Scene
    control: str
    table: pd.DataFrame = FrameField()
    points: pd.DataFrame = FrameField()
    rejections: pd.DataFrame = FrameField()
    status: str
    outcome: Outcome
    states: list = field(repr=False, default_factory=list)
    stats: dict = field(default_factory=dict)

    def limit_points(self) -> pd.DataFrame:
        """The limit points (named EMI under voltage control)."""
        return self.points[self.points["kind"].isin([PointKind.LP.value, PointKind.EMI.value])]

    def critical_state(self, k: int) -> Point:
        """The located state of row ``k`` of the points table."""
        if not -len(self.points) <= k < len(self.points):
            raise SnapmemError(f"point row {k}: the branch has {len(self.points)} critical points "
                               f"(rows 0..{len(self.points) - 1})")
        s = float(self.points["s"].iloc[k])
        return min((p for p in self.states if p.kind in (PointKind.LP, PointKind.BP)), key=lambda p: abs(p.s - s))

    def scene_state(self, p: Point) -> np.ndarray:
        """The full state q [m] of point ``p``."""
        return make_problem(self.scene, self.control).state(p.x, p.lam)[0]

    def switch(self, k: int, **kwargs):
        """Switch to the branch bifurcating at row ``k`` of the points table and trace it both ways:
        a :class:`~snapmem.continuation.diagram.Diagram` of this branch and the two new halves
        (keywords: those of :func:`snapmem.continuation.switching.switch_branch`, which
        registers itself in :data:`BRANCH_SWITCHING` when snapmem.continuation is imported: the
        switch traces new branches, and the tracer imports this module)."""
        if not BRANCH_SWITCHING:
            raise SnapmemError("branch switching is not available: import snapmem.continuation")
        return BRANCH_SWITCHING[0](self, k, **kwargs)


    def save(self, path) -> None:
        """Save every point's state, tangent, inertia and step as a compressed .npz (no pickle).

        Arrays: ``x`` (M, n) unknowns, ``q`` (M, 2N) full states, ``lam`` (M,), ``tangent``
        (M, n + 1; NaN where none), ``negative_eigs`` (M,), ``s``, ``ds``, ``kind`` (M,) str,
        and ``meta``, a JSON string with the scene name and parameters and the control.
        """
        M = len(self.states)
        n = self.states[0].x.size if M else 0
        tangent = np.full((M, n + 1), np.nan)
        for i, p in enumerate(self.states):
            if p.tangent is not None:
                tangent[i] = p.tangent
        problem = make_problem(self.scene, self.control)
        write_npz(
            path, x=np.array([p.x for p in self.states]), lam=np.array([p.lam for p in self.states]),
            q=np.array([problem.state(p.x, p.lam)[0] for p in self.states]), tangent=tangent,
            negative_eigs=np.array([-1 if p.negative is None else p.negative for p in self.states]),
            s=np.array([p.s for p in self.states]), ds=np.array([p.ds for p in self.states]),
            kind=np.array([PointKind(p.kind).value for p in self.states], dtype=str),
            meta=np.array(json.dumps({"scene": self.scene.name, "parameters": _jsonable(self.scene.parameters),
                                      "control": self.control})))


def load_points(path) -> dict:
    """Read a branch file written by :meth:`Branch.save` (no pickle); returns its arrays and meta."""
    out = read_npz(path, "branch file", required=("x", "lam", "meta"))
    out["meta"] = json.loads(str(out["meta"]))
    return out


def _jsonable(d):
    return {k: (v if isinstance(v, (str, int, float, bool)) or v is None else str(v)) for k, v in d.items()}


#: The branch-switching function (snapmem.continuation.switching.switch_branch), registered on import.
BRANCH_SWITCHING: list = []
