"""Newton's outcomes and acceptance rules (snapmem.solvers.status, snapmem.solvers.rules), and the
scalar formulas that the compiled kernels and the numpy reference share."""

import json

import numpy as np
import pytest

import snapmem
from snapmem.kernels import switch
from snapmem.kernels.assembly import swept_volume
from snapmem.kernels.contact import barrier_force, ipc_barrier
from snapmem.kernels.laws import electric_density, first_invariant, gent_invariants
from snapmem.solvers import rules
from snapmem.solvers.newton import STATUSES, NewtonReport
from snapmem.solvers.status import Status


def test_status_values_are_todays_words():
    assert [s.value for s in Status] == ["converged", "max_iterations", "step_too_small", "left_domain", "singular",
                                         "not_finite", "no_equilibrium", "failed"]
    assert list(STATUSES) == [s.value for s in Status]
    report = NewtonReport(False, 3, 1.0, "singular tangent stiffness", status=Status.singular)
    assert report.status == "singular" and str(report.status) == f"{report.status}" == "singular"
    assert json.dumps({"status": report.status}) == '{"status": "singular"}'


def test_rules_accept_as_documented():
    q = np.array([1.0, -2.0])
    assert rules.converged(1e-9, 1e-8, 0.0, np.inf, q)
    assert not rules.converged(1e-7, 1e-8, 0.0, np.inf, q)
    assert rules.converged(1e-7, 1e-8, 0.0, 1e-12, q)                  # at the rounding of q
    assert rules.converged(1e-7, 1e-8, 2e-7, np.inf, q)                # the residual's floor
    assert rules.energy_step_accepted(0.5, 10.0, 1.0, 1.0, 1.0, -1.0)
    assert rules.energy_step_accepted(2.0, 0.4, 1.0, 1.0, 1.0, -1.0)   # max |R| halved
    assert not rules.energy_step_accepted(np.inf, 0.1, 1.0, 1.0, 1.0, -1.0)
    assert rules.residual_step_accepted(0.5, 1.0, 1.0) and not rules.residual_step_accepted(1.0, 1.0, 1.0)
    assert rules.inertia_tolerance(1.0, 0.0, 1.0) == 1.0
    assert rules.RULES.cut == rules.CUT == 0.5


def test_one_switch_nests():
    assert switch.compiled()
    with snapmem.reference_path():
        with snapmem.reference_path():
            assert not switch.compiled()
        assert not switch.compiled()
    assert switch.compiled()


def test_compiled_formulas_are_their_python_originals():
    rng = np.random.default_rng(0)
    d = rng.uniform(1e-4, 1e-3, 5)
    for x in d:
        assert ipc_barrier(x, 1e-3, 2.5) == pytest.approx(ipc_barrier.py_func(x, 1e-3, 2.5), rel=1e-15)
        assert barrier_force(x, 1e-3, 2.5) == abs(ipc_barrier(x, 1e-3, 2.5)[1])
    assert barrier_force(2e-3, 1e-3, 2.5) == 0.0
    l1, l2 = 1.3, 0.8
    assert gent_invariants(first_invariant(l1, l2), 1.0, 20.0) == pytest.approx(
        gent_invariants.py_func(first_invariant.py_func(l1, l2), 1.0, 20.0), rel=1e-15)
    assert electric_density(l1, l2, 0.7) == pytest.approx(electric_density.py_func(l1, l2, 0.7), rel=1e-15)
    assert swept_volume(1.0, 2.0, 0.5, -3.0) == pytest.approx(swept_volume.py_func(1.0, 2.0, 0.5, -3.0), rel=1e-15)
