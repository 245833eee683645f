import numpy as np
import pytest

from snapmem import build_scene
from snapmem.kernels.banded import BandedLDLT, BandedLU, BandedMatrix, BorderedMatrix


@pytest.mark.parametrize("name", ["balloon", "torus"])
def test_band_storage_solve_and_eigenvalues_match_dense(name):
    scene = build_scene(name, nodes=24, pressure=0.013)
    rng = np.random.default_rng(3)
    q = scene.reference_state() * 1.4 + rng.normal(scale=0.05, size=48)
    q[list(scene.fixed)] = scene.reference_state()[list(scene.fixed)]
    K = scene.evaluate(q).stiffness
    dense = K.to_dense()
    assert np.allclose(BandedMatrix.from_dense(dense, K.b).to_dense(), dense)
    x = rng.normal(size=K.n)
    np.testing.assert_allclose(K.matvec(x), dense @ x, atol=1e-12 * np.abs(dense).max())
    rhs = rng.normal(size=(K.n, 2))
    np.testing.assert_allclose(dense @ K.factor().solve(rhs), rhs, atol=1e-9)
    eig = np.linalg.eigvalsh(dense)
    np.testing.assert_allclose(K.smallest_eigenvalues(3), eig[:3], atol=1e-10 * np.abs(eig).max())
    assert K.negative_count() == np.count_nonzero(eig < 0)


def test_closed_meridian_band_is_five_open_is_three():
    assert build_scene("torus", nodes=50).bandwidth == 5
    assert build_scene("balloon", nodes=51).bandwidth == 3


def _random_band(n, b, shift, seed):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    dense = np.zeros((n, n))
    for d in range(-b, b + 1):
        dense += np.diag(np.diagonal(A, d), d)
    return 0.5 * (dense + dense.T) + shift * np.eye(n)


@pytest.mark.parametrize("b", [1, 3, 5])
@pytest.mark.parametrize("shift", [-2.0, 0.0, 0.7])
def test_ldlt_inertia_counts_negative_eigenvalues_of_random_band_matrices(b, shift):
    dense = _random_band(60, b, -shift, seed=b * 100 + int(shift * 10) + 50)
    K = BandedMatrix.from_dense(dense, b)
    assert K.negative_count() == np.count_nonzero(np.linalg.eigvalsh(dense) < 0)


@pytest.mark.parametrize("name", ["balloon", "torus"])
def test_eigenvalues_near_zero_match_dense(name):
    scene = build_scene(name, nodes=40)
    rng = np.random.default_rng(5)
    q = scene.reference_state() * 1.5
    q[scene.free] += rng.normal(scale=0.02, size=scene.n_free)
    K = scene.evaluate(q, {"pressure": 0.012}).stiffness
    values, vectors = K.eigenvalues_near_zero(3)
    eig = np.linalg.eigvalsh(K.to_dense())
    nearest = np.sort(eig[np.argsort(np.abs(eig))[:3]])
    scale = np.abs(eig).max()
    np.testing.assert_allclose(values, nearest, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(np.abs(vectors.T @ vectors), np.eye(3), atol=1e-10)


@pytest.mark.parametrize("shift", [6.0, 0.3])          # positive definite; indefinite
@pytest.mark.parametrize("b", [1, 3, 5])
def test_ldlt_solves_where_stable_and_carries_the_inertia(b, shift):
    dense = _random_band(80, b, shift, seed=b)
    K = BandedMatrix.from_dense(dense, b)
    lu = K.factor()
    rhs = np.random.default_rng(0).normal(size=(80, 3))
    x = lu.solve(rhs)
    assert np.abs(dense @ x - rhs).max() <= 1e-12 * np.abs(dense).max() * np.abs(x).max()
    np.testing.assert_allclose(lu.solve(rhs[:, 0]), x[:, 0], rtol=1e-14)
    assert lu.negative == np.count_nonzero(np.linalg.eigvalsh(dense) < 0) == K.negative_count()
    np.testing.assert_allclose(K.matvec(x), dense @ x, atol=1e-12 * np.abs(dense @ x).max())
    if shift > 5:
        assert isinstance(lu, BandedLDLT)


@pytest.mark.parametrize("pivot", [0.0, 1e-13])
def test_ldlt_falls_back_to_pivoted_lu_on_a_zero_or_tiny_pivot(pivot):
    """Without pivoting, a tiny first pivot of an indefinite K makes the factors grow by 1/pivot
    (here 1e13): the solve must come from LAPACK's pivoted LU, and be accurate."""
    dense = _random_band(40, 3, 0.0, seed=9)
    dense[0, 0] = pivot
    dense[1, 0] = dense[0, 1] = 1.0
    K = BandedMatrix.from_dense(dense, 3)
    from snapmem.kernels.linalg import band_ldlt
    _, _, zero, growth = band_ldlt(K.lower(), 3)
    assert zero == 1 if pivot == 0 else growth > 1e10
    lu = K.factor()
    assert isinstance(lu, BandedLU) and not lu.singular
    rhs = np.arange(40.0)
    x = lu.solve(rhs)
    assert np.abs(dense @ x - rhs).max() <= 1e-12 * np.abs(dense).max() * np.abs(x).max()
    assert lu.negative == np.count_nonzero(np.linalg.eigvalsh(dense) < 0)


def test_bordered_solve_reuses_the_inner_factorisation_and_is_accurate_at_a_singular_band():
    """BEMW with refinement: K singular (a fold), the bordered matrix regular."""
    dense = _random_band(30, 3, 0.0, seed=4)
    w, V = np.linalg.eigh(dense)
    dense -= w[0] * np.outer(V[:, 0], V[:, 0])        # K exactly singular along V[:, 0]
    K = BandedMatrix.from_dense(dense, 3)
    border = V[:, 0] + 0.1
    M = BorderedMatrix(K, border, border, [[0.0]])
    rhs = np.linspace(-1.0, 1.0, 31)
    exact = np.linalg.solve(M.to_dense(), rhs)
    for lu in (M.factor(), M.factor(K.factor())):
        np.testing.assert_allclose(lu.solve(rhs), exact, rtol=0, atol=1e-9 * np.abs(exact).max())


def test_refinement_policy_is_an_argument_of_both_bordered_solves():
    """BorderedLU and the compiled bordered_solve take the same REFINE_* policies: at a fold (the
    Schur complement a small difference of large terms) cancellation asks for the refinement step."""
    from snapmem.kernels.bordered import bordered_solve
    from snapmem.kernels.linalg import REFINE_ALWAYS, REFINE_NEVER, REFINE_ON_CANCELLATION, needs_refinement
    K = BandedMatrix.from_dense(_random_band(30, 3, 10.0, seed=4), 3)          # positive definite band
    border = np.linspace(0.5, 1.5, 30)
    corner = float(border @ np.linalg.solve(K.to_dense(), border)) * (1.0 + 1e-7)   # S = 1e-7 of its terms
    M = BorderedMatrix(K, border, border, [[corner]])
    rhs = np.linspace(-1.0, 1.0, 31)
    exact = np.linalg.solve(M.to_dense(), rhs)
    for policy in (REFINE_NEVER, REFINE_ON_CANCELLATION, REFINE_ALWAYS):
        lu = M.factor(refine=policy)
        np.testing.assert_allclose(lu.solve(rhs), exact, rtol=0, atol=1e-6 * np.abs(exact).max())
        x, ok = bordered_solve(K.lower(), border[None, :], np.array([[corner]]), rhs, policy)
        assert ok
        np.testing.assert_allclose(x, exact, rtol=0, atol=1e-6 * np.abs(exact).max())
        assert lu.refine == policy
    S, terms = np.array([[1e-9]]), np.array([[1.0]])
    assert [needs_refinement(p, S, terms) for p in (REFINE_NEVER, REFINE_ON_CANCELLATION, REFINE_ALWAYS)] == [
        False, True, True]
    assert not needs_refinement(REFINE_ON_CANCELLATION, np.array([[0.5]]), terms)


def test_lu_is_the_documented_alias_of_factor():
    K = BandedMatrix.from_dense(_random_band(12, 2, 5.0, seed=1), 2)
    assert BandedMatrix.lu is BandedMatrix.factor and BorderedMatrix.lu is BorderedMatrix.factor
    assert type(K.lu()) is type(K.factor())
