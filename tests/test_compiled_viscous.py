"""The compiled time step on viscoelastic and prestretched scenes (issue 15): the same run as the
general (numpy) path to round-off, the networks' internal stretches and dissipation included."""

import numpy as np
import pytest

import snapmem
from snapmem.catalog.registry import build_scene
from snapmem.catalog.robots import experiment
from snapmem.dynamics.compiled_step import CompiledStep
from snapmem.dynamics.driver import simulate
from snapmem.dynamics.options import DynamicsOptions

P = 0.012


def both_paths(run):
    """The run on the compiled step, then on the general path."""
    fast = run()
    with snapmem.reference_path():
        general = run()
    return fast, general


def assert_same_run(fast, general, keys, rel=1e-11):
    assert fast.meta["status"] == general.meta["status"] == "completed"
    assert fast.meta["steps"] == general.meta["steps"]
    assert fast.meta["newton_iterations"] == general.meta["newton_iterations"]
    for key in keys:
        scale = max(np.max(np.abs(general[key])), 1e-300)
        assert np.max(np.abs(fast[key] - general[key])) <= rel * scale, key


def balloon_run(scene, t_end=0.3, scheme="bdf2"):
    options = DynamicsOptions(scheme=scheme, dt=0.01, adaptive=False, save_interval=0.0)
    return lambda: simulate(scene, {"pressure": [(0.0, 0.0), (0.005, P), (t_end, P)]}, t_end, rho=1e-6,
                            damping=1e3, options=options)


@pytest.mark.parametrize("params", [dict(viscous_mu=0.5, relaxation_time=1.0),
                                    dict(viscous_mu="0.5,0.2", relaxation_time="1,0.05", viscous_Jlim="0.3,5")],
                         ids=["neo-Hookean network", "two networks, Gent"])
def test_viscous_balloon_compiled_is_the_general_path(params):
    scene = build_scene("balloon", nodes=21, **params)
    assert CompiledStep.of(scene) is not None
    fast, general = both_paths(balloon_run(scene))
    assert_same_run(fast, general, ("q", "xi", "potential", "dissipation", "volume"))
    assert np.all(general["xi"][-1] > 1.0) and general["dissipation"][-1] > 0.0      # the networks did flow


def test_prestretched_balloon_compiled_is_the_general_path():
    scene = build_scene("balloon", nodes=21, material="gent", mu=1.0, Jlim=20.0, prestretch_1=1.3, prestretch_2=1.5)
    assert CompiledStep.of(scene).plan.law_stretch.tolist() == [1.3, 1.5]
    fast, general = both_paths(balloon_run(scene, t_end=0.1))
    assert_same_run(fast, general, ("q", "potential", "volume"))
    assert np.max(np.abs(general["q"][-1] - general["q"][0])) > 0.1          # it moved


@pytest.mark.slow
def test_viscous_prestretched_robot_compiled_is_the_general_path():
    """The ball thrown by a prestretched viscoelastic balloon (bodies, contact, a ramp): its first 0.2 s."""
    ex = experiment("ball_throw", viscous_mu=1e5, relaxation_time=0.05, prestretch=1.2)
    assert CompiledStep.of(ex.scene) is not None

    def run():
        return simulate(ex.scene, ex.loads, 0.2, rho=ex.rho, damping=ex.damping, q0=ex.q0, v0=ex.v0,
                        options=ex.options, damp_bodies=ex.damp_bodies)

    fast, general = both_paths(run)
    assert_same_run(fast, general, ("q", "xi", "potential", "dissipation", "ball_force", "min_gap"), rel=1e-9)
    assert general["dissipation"][-1] > 0.0
