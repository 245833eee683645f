"""Snap-through: from a state (a located limit point pushed past) to rest on the far branch."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from snapmem.dynamics.driver import simulate
from snapmem.dynamics.loads import as_schedule
from snapmem.dynamics.options import DynamicsOptions
from snapmem.dynamics.trajectory import Trajectory
from snapmem.errors import check_real
from snapmem.model.scene import Scene
from snapmem.solvers.newton import solve

log = logging.getLogger(__name__)


@dataclass
class Settled:
    """The rest state reached by :func:`settle`.

    Attributes
    ----------
    q : ndarray (n_dof,)
        Equilibrium polished by a static Newton solve at the final loads (if it converged).
    loads : dict
    trajectory : Trajectory
    at_rest : bool
        Whether the motion died out before ``t_max`` and the static polish converged.
    """

    q: np.ndarray
    loads: dict
    trajectory: Trajectory
    at_rest: bool


def settle(scene: Scene, q: np.ndarray, loads=None, rho: float = 1.0, damping: float = 1.0,
           t_max: float = 1e3, rest_tol: float = 1e-6,
           options: DynamicsOptions = DynamicsOptions(scheme="bdf2", tol=1e-3),
           v0: np.ndarray | None = None) -> Settled:
    """Run the damped dynamics from q (e.g. just past a limit point) until it comes to rest.

    Parameters
    ----------
    scene : Scene
    q : ndarray (n_dof,)
        Starting state (at rest unless ``v0``).
    loads : mapping or schedule
        Loads (constant, or in time); default the scene's.
    rho, damping : float
        Membrane density [kg/m^3] and mass-proportional damping xi [1/s] (> 0 to come to rest).
    t_max : float
        Give up after this long [s].
    rest_tol : float
        At rest when the speed is below rest_tol * L * xi and the acceleration below
        rest_tol * L * xi^2 (L the meridian size): what motion is left would move a node by
        less than about rest_tol * L.

    Returns
    -------
    Settled
        The rest state (polished to a static equilibrium with :func:`snapmem.solvers.newton.solve`), the
        loads there and the trajectory: hand it back to continuation to go on along the far
        branch, ``trace(scene, control, start=(rest.q, rest.loads))``. The default integrator is
        BDF2 at a loose tolerance: only where the motion ends matters, not its path.
    """
    at = as_schedule(loads if loads is not None else {})
    check_real("damping", damping, minimum=0.0, min_inclusive=False)
    length = scene.meridian.size
    free = scene.free
    vmax, amax = rest_tol * length * damping, rest_tol * length * damping ** 2
    state = {"v_prev": None, "t_prev": None}

    def at_rest(t, q_now, v_now):
        prev, t_prev = state["v_prev"], state["t_prev"]
        state["v_prev"], state["t_prev"] = v_now.copy(), t
        if prev is None or np.max(np.abs(v_now[free])) > vmax:
            return False
        return np.max(np.abs((v_now - prev)[free])) / max(t - t_prev, 1e-300) <= amax

    traj = simulate(scene, at, t_max, rho=rho, damping=damping, q0=q, v0=v0, options=options, stop=at_rest)
    q_end = traj.final_q
    final_loads = scene.resolve_loads(at(float(traj["t"][-1])))
    eq = solve(scene, final_loads, q0=q_end)
    moved = np.max(np.abs(eq.q - q_end)) if eq.converged else np.inf
    ok = bool(eq.converged and moved <= 1e3 * rest_tol * length and traj["t"][-1] < t_max)
    log.info("settle: t = %.4g s, static polish %s, moved %.3g m", traj["t"][-1], eq.report.reason, moved)
    return Settled(eq.q if eq.converged else q_end, final_loads, traj, ok)
