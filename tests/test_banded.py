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
