"""The balloon's supports (issue 16, item 3): 'pole' holds the south pole's z, 'free' holds the
centre-of-mass height by a Lagrange multiplier and keeps the mesh's up-down symmetry, so that
the sphere's odd P_n modes are exact bifurcations."""

import numpy as np
import pytest

from snapmem.catalog.scenes import get_spec
from snapmem.continuation import trace
from snapmem.continuation.problems import make_problem
from snapmem.errors import SnapmemError
from snapmem.model.constraints import CentreOfMassHeight, multiplier_count
from snapmem.model.dofs import node_areas
from snapmem.reference.exact import balloon_stretch, sphere_bifurcation_stretches
from snapmem.statics import equilibrium


def balloon(support, nodes=41, **params):
    return get_spec("balloon").build(("pressure",), nodes=nodes, support=support, **params)


def test_free_equilibrium_is_the_held_one_translated_and_symmetric():
    pole, free = balloon("pole"), balloon("free")
    loads = {"pressure": 0.012}
    a, b = equilibrium(pole, loads), equilibrium(free, loads)
    assert a.converged and b.converged
    n = free.meridian.nodes
    r, z = b.q[0:2 * n:2], b.q[1:2 * n:2]
    assert np.max(np.abs(r - r[::-1])) < 1e-10 * r.max()          # up-down symmetric
    assert np.max(np.abs(z + z[::-1])) < 1e-10 * r.max()
    weights = node_areas(free.meridian)
    assert abs(weights @ (z - free.meridian.z)) < 1e-12 * r.max()   # the constraint holds
    assert abs(b.q[2 * n]) < 1e-8 * r.max()                         # no net axial force: no reaction
    shift = a.q[1:2 * n:2] - z                                       # the held pole's state is a translation
    assert np.ptp(shift) < 1e-9 * r.max()
    assert np.max(np.abs(a.q[0:2 * n:2] - r)) < 1e-9 * r.max()
    assert free.measures(b.q)["stretch"] == pytest.approx(balloon_stretch(0.012), abs=2e-3)


def test_stability_counts_the_constrained_stiffness():
    """The saddle matrix [[K, c], [c^T, 0]] has one negative eigenvalue more than K on the
    constraint's tangent space; the reported count is the latter, and equals the held pole's
    (both remove the same rigid translation)."""
    pole, free = balloon("pole", E_hat=0.4), balloon("free", E_hat=0.4)
    assert multiplier_count(free) == 1 and multiplier_count(pole) == 0
    for stretch in (1.2, 1.6, 2.2):            # before the LP, between LP and P1, after P1
        q = {}
        for scene in (pole, free):
            branch = trace(scene, "pressure", until={"stretch": stretch})
            q[scene] = branch.states[-1]
        counts = [p.negative for p in q.values()]
        assert counts[0] == counts[1]
        pb = make_problem(free, "pressure")
        _, J = pb.evaluate(q[free].x, q[free].lam)
        dense = J.to_dense()
        n_free = dense.shape[0] - 1
        c = dense[:n_free, -1]
        basis = np.linalg.svd(c[None, :])[2][1:].T                  # the tangent space c . dq = 0
        restricted = np.linalg.eigvalsh(basis.T @ dense[:n_free, :n_free] @ basis)
        assert counts[1] == int(np.sum(restricted < 0))
        assert int(np.sum(np.linalg.eigvalsh(dense) < 0)) == counts[1] + 1


@pytest.fixture(scope="module")
def free_branches():
    return {n: trace(balloon("free", nodes=n, E_hat=0.5), "pressure", until={"stretch": 2.0}) for n in (51, 101)}


def test_odd_modes_are_exact_bifurcations_under_free_support(free_branches):
    errors = {}
    for n, branch in free_branches.items():
        pts = branch.points
        assert list(pts["kind"]) == ["LP", "BP", "BP", "BP"]
        assert list(pts["mode"]) == [-1, 1, 2, 3]
        odd = pts[pts["mode"].isin([1, 3])]
        assert (odd["coupling"] < 1e-7).all() and not odd["symmetry_broken"].any()   # exact, by symmetry
        assert pts["symmetry_broken"].iloc[2]                                        # P2: the mesh breaks it
        for mode in (1, 2, 3):
            row = pts[pts["mode"] == mode].iloc[0]
            errors.setdefault(mode, []).append(row["stretch"] - sphere_bifurcation_stretches(mode, E_hat=0.5)[0])
    for mode, (coarse, fine) in errors.items():
        assert abs(coarse) < 3e-3
        assert 1.8 < np.log2(abs(coarse) / abs(fine)) < 2.2                          # N^-2
    assert errors[1][0] < 0 < errors[3][0]


def test_bad_support_is_one_clear_error():
    with pytest.raises(SnapmemError, match="support = 'side': must be one of pole, free"):
        balloon("side")
    with pytest.raises(SnapmemError, match="area"):
        CentreOfMassHeight(np.zeros(3), np.zeros(3), 1.0)
