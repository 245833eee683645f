import numpy as np
import pytest

from snapmem import build_scene
from snapmem.banded import BandedMatrix


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
    np.testing.assert_allclose(dense @ K.lu().solve(rhs), rhs, atol=1e-9)
    eig = np.linalg.eigvalsh(dense)
    np.testing.assert_allclose(K.smallest_eigenvalues(3), eig[:3], atol=1e-10 * np.abs(eig).max())
    assert K.negative_count() == np.count_nonzero(eig < 0)


def test_closed_meridian_band_is_five_open_is_three():
    assert build_scene("torus", nodes=50).bandwidth == 5
    assert build_scene("balloon", nodes=51).bandwidth == 3


@pytest.mark.parametrize("b", [1, 3, 5])
@pytest.mark.parametrize("shift", [-2.0, 0.0, 0.7])
def test_ldlt_inertia_counts_negative_eigenvalues_of_random_band_matrices(b, shift):
    rng = np.random.default_rng(b * 100 + int(shift * 10) + 50)
    n = 60
    A = rng.normal(size=(n, n))
    dense = np.zeros((n, n))
    for d in range(-b, b + 1):
        dense += np.diag(np.diagonal(A, d), d)
    dense = 0.5 * (dense + dense.T) - shift * np.eye(n)
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
