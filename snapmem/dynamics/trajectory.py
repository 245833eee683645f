"""The recorded frames of a simulation (:class:`Trajectory`), and their .npz files."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from enum import Enum

import numpy as np


class RunOutcome(str, Enum):
    """How a simulation ended: ``meta['outcome']`` (the value is the word; ``meta['status']`` says
    it in a sentence, with the time and the limit)."""

    completed = "completed"            # t_end reached
    stopped = "stopped"                # the caller's stop condition ended it
    interrupted = "interrupted"        # SIGINT or SIGTERM, taken between two steps
    max_steps = "max_steps"            # DynamicsOptions.max_steps reached
    dt_min = "dt_min"                  # the step fell below DynamicsOptions.dt_min

    def __str__(self) -> str:
        return self.value

    __format__ = str.__format__


@dataclass
class Trajectory:
    """Recorded frames of a simulation, and how the run went.

    Attributes
    ----------
    data : dict of str -> ndarray
        Per frame (T rows): ``t`` [s], ``r``, ``z`` (T, N) [m], ``v`` (T, n_dof) [m/s],
        ``load_<name>``, ``volume`` [m^3], ``kinetic``, ``potential``, ``total`` [J], ``dt`` [s],
        ``newton`` (iterations of the step), ``min_gap`` [m] (smallest contact gap over all
        accepted steps since the previous frame; inf without contact), and for each contact
        ``<body>_force`` [N] and ``<body>_gap`` [m], for each rigid body ``<name>_z`` [m] and
        ``<name>_v`` [m/s], and the failure margins ``breakdown_margin`` and ``rupture_margin``
        (each fails at 1, inf where the scene sets no limit:
        :func:`snapmem.model.local_checks.failure_margins`).
        A scene with viscous networks (:mod:`snapmem.model.viscous`) adds ``xi`` (T, K, 2, E), the
        internal stretches (meridional, hoop) of each of its K networks on every edge, and
        ``dissipation`` [J], the energy its dashpots dissipated since the start; its ``potential``
        includes the networks' stored energy at each frame's internal stretches.
    meta : dict
        Scene name and parameters, scheme, rho, damping, step and iteration counts, wall time;
        ``outcome`` (a :class:`RunOutcome` word) and ``status`` ('completed', or the sentence
        that says why the run ended early).
    """

    data: dict
    meta: dict = field(default_factory=dict)

    def __getitem__(self, key) -> np.ndarray:
        return self.data[key]

    @property
    def final_q(self) -> np.ndarray:
        return self.data["q"][-1]

    def save(self, path):
        """Write a compressed .npz that loads without pickle (meta as a JSON string); atomically, so
        an interrupted save leaves no half file. Returns the path written ('.npz' appended if missing)."""
        from snapmem.io.results import write_npz
        arrays = {k: np.asarray(v) for k, v in self.data.items()}
        arrays["meta"] = np.array(json.dumps(self.meta, default=_json_default))
        return write_npz(path, **arrays)

    @classmethod
    def load(cls, path) -> "Trajectory":
        from snapmem.errors import read_npz                     # corrupt or truncated: one clear error
        data = read_npz(path, "trajectory file", required=("t", "r", "z"))
        meta = json.loads(str(data.pop("meta"))) if "meta" in data else {}
        return cls(data, meta)

    def snap_time(self, key: str = "volume") -> float:
        """Time of the fastest change of ``key`` (a snap-through or snap-back) [s]."""
        t, y = self.data["t"], self.data[key]
        rate = np.abs(np.diff(y) / np.maximum(np.diff(t), 1e-300))
        i = int(np.argmax(rate))
        return float(0.5 * (t[i] + t[i + 1]))

    def failure_time(self, margin: str = "breakdown_margin") -> float | None:
        """The time [s] a failure margin (``breakdown_margin``, ``rupture_margin``) first reaches 1,
        interpolated linearly between the two frames around it (the EB and RU events of a run);
        None if it never does (or the trajectory has no such column)."""
        values = self.data.get(margin)
        if values is None:
            return None
        t = self.data["t"]
        below = np.flatnonzero(values <= 1.0)
        if below.size == 0:
            return None
        i = int(below[0])
        if i == 0 or not np.isfinite(values[i - 1]):
            return float(t[i])
        w = (values[i - 1] - 1.0) / (values[i - 1] - values[i])
        return float(t[i - 1] + w * (t[i] - t[i - 1]))


def _json_default(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return str(x)

