"""The Python twins of the loop kernels (snapmem._lazy.Kernel.python_twin): what runs on first use,
before numba's cache holds a kernel. Each must give the compiled kernel's numbers bit for bit, on
any shape the kernel takes, including the edge cases of the band (n <= b, one right-hand side)."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from snapmem.kernels import linalg


def compiled(kernel):
    """The numba dispatcher of a kernel (the module's name may already be rebound to it)."""
    return getattr(kernel, "dispatcher", kernel)


from snapmem.solvers import rules  # noqa: E402

MAX_ABS = rules.max_abs                  # the Kernel (its module name is rebound once it compiles)
KERNELS = {name: getattr(linalg, name) for name in
           ("band_ldlt", "band_ldlt_solve", "_ldlt_solve_vector", "orthonormal", "ritz_step", "band_matvec")}


def band(rng, n, b, shift):
    lower = rng.normal(size=(b + 1, n))
    lower[0] += shift                    # shift 0: indefinite, with negative pivots
    return lower


def same(a, b):
    return np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)


shapes = st.tuples(st.integers(1, 40), st.integers(1, 5), st.integers(1, 9), st.integers(0, 2 ** 32 - 1),
                   st.sampled_from([0.0, 4.0]))


@settings(max_examples=40, deadline=None)
@given(shapes)
def test_band_twins_are_the_compiled_kernels_bit_for_bit(shape):
    n, b, cols, seed, shift = shape
    rng = np.random.default_rng(seed)
    lower = band(rng, n, b, shift)
    K = KERNELS
    expected = compiled(K["band_ldlt"])(lower, b)
    got = K["band_ldlt"]._twin(lower, b)
    assert same(got[0], expected[0]) and tuple(got[1:]) == tuple(expected[1:])
    F = expected[0]
    x = rng.normal(size=(n, cols))
    a, c = x.copy(), x.copy()
    K["band_ldlt_solve"]._twin(F, a)
    compiled(K["band_ldlt_solve"])(F, c)
    assert same(a, c)
    v = rng.normal(size=n)
    a, c = v.copy(), v.copy()
    K["_ldlt_solve_vector"]._twin(F, a)
    compiled(K["_ldlt_solve_vector"])(F, c)
    assert same(a, c)
    assert same(K["band_matvec"]._twin(lower, x), compiled(K["band_matvec"])(lower, x))


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 60), st.integers(1, 10), st.integers(0, 2 ** 32 - 1))
def test_subspace_twins_are_the_compiled_kernels_bit_for_bit(n, m, seed):
    m = min(m, n)
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(n, m))
    orthonormal, ritz = KERNELS["orthonormal"], KERNELS["ritz_step"]
    V = compiled(orthonormal)(X)
    assert same(orthonormal._twin(X), V)
    W = rng.normal(size=(n, m))
    theta_t, V_t = ritz._twin(V, W)
    theta_c, V_c = compiled(ritz)(V, W)
    assert same(theta_t, theta_c) and same(V_t, V_c)


def test_a_solve_of_a_singular_leading_block_replaces_the_zero_pivot_in_both():
    lower = np.array([[0.0, 2.0, 3.0], [1.0, 1.0, 0.0]])
    got, expected = KERNELS["band_ldlt"]._twin(lower, 1), compiled(KERNELS["band_ldlt"])(lower, 1)
    assert got[2] == expected[2] == 1 and same(got[0], expected[0])


def test_the_twin_runs_while_the_kernel_runs_as_python(monkeypatch):
    import snapmem._lazy as lazy
    calls = []
    kernel = lazy.Kernel(lambda x: x + 1.0, {"cache": True})

    @kernel.python_twin
    def plus_one(x):
        calls.append(x)
        return x + 1.0

    assert kernel.python is plus_one
    monkeypatch.setitem(lazy._policy, "compile", False)
    monkeypatch.setattr(lazy, "_in_cache", lambda k: False)
    monkeypatch.setattr(lazy, "_seen", {})
    assert kernel(1.0) == 2.0 and calls == [1.0]


@pytest.mark.parametrize("name", sorted(KERNELS))
def test_every_twin_keeps_the_kernels_name_and_is_not_what_numba_compiles(name):
    kernel = KERNELS[name]
    assert kernel._twin is not None and kernel._twin is not kernel.py_func
    assert kernel.__name__ == name


@pytest.mark.parametrize("values", [[], [-0.0], [0.0, -3.0, 2.0], [1.0, np.nan, 5.0], [np.inf, -np.inf], [-1e-300, 2e-308]])
def test_max_abs_is_numpys_max_of_abs_compiled_and_as_python(values):
    x = np.array(values, dtype=float)
    expected = float(np.max(np.abs(x))) if x.size else 0.0
    for f in (compiled(MAX_ABS), MAX_ABS._twin, MAX_ABS.py_func, rules.max_norm):
        assert same(f(x), expected)


from snapmem.kernels import assembly  # noqa: E402

ASSEMBLY = {name: getattr(assembly, name) for name in
            ("edge_assembly", "linear_law_density", "volume_gradient", "state_check")}


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 30), st.integers(0, 2 ** 32 - 1), st.sampled_from([0.0, 0.37]), st.sampled_from([1, 2]))
def test_assembly_twins_are_the_compiled_kernels_bit_for_bit(n_edges, seed, pressure, order):
    """The edge assembly (gradient, band, volume, largest force), the linear law, the volume
    gradient: the edge arithmetic on arrays and the scatter by np.add.at, against the loops."""
    rng = np.random.default_rng(seed)
    n = n_edges + 1
    q = np.abs(rng.normal(size=2 * n)) + 0.5
    edges = np.stack([np.arange(n_edges), np.arange(1, n_edges + 1)], axis=1).astype(np.int64)
    inv_length, inv_mid_radius, weight = (np.abs(rng.normal(size=n_edges)) + 0.1 for _ in range(3))
    derivatives = [rng.normal(size=n_edges) for _ in range(5)]
    n_band = 7 * n
    band_index = rng.integers(0, n_band + 1, size=16 * n_edges).astype(np.int64)   # repeats accumulate
    args = (q, edges, inv_length, inv_mid_radius, weight, *derivatives, pressure, band_index, n_band, order)
    kernel = ASSEMBLY["edge_assembly"]
    for got, expected in zip(kernel._twin(*args), compiled(kernel)(*args)):
        assert same(got, expected)
    lam1, lam2 = np.abs(rng.normal(size=(2, n_edges))) + 0.3
    law = ASSEMBLY["linear_law_density"]
    for got, expected in zip(law._twin(lam1, lam2, 0.4375, 0.0625), compiled(law)(lam1, lam2, 0.4375, 0.0625)):
        assert same(got, expected) and got.shape == (n_edges,)
    gradient = ASSEMBLY["volume_gradient"]
    assert same(gradient._twin(q, edges, q.size), compiled(gradient)(q, edges, q.size))


@pytest.mark.parametrize("bad, expected", [(None, -1), ((2, -1.0), 2), ((4, 0.0), 4), ((1, np.nan), -2),
                                           ((3, np.inf), -2)])
def test_state_check_twin_finds_what_the_kernel_finds(bad, expected):
    q = np.arange(1.0, 9.0)
    if bad is not None:
        q[bad[0]] = bad[1]
    radius_dofs = np.arange(0, 8, 2, dtype=np.int64)
    kernel = ASSEMBLY["state_check"]
    assert kernel._twin(q, radius_dofs) == compiled(kernel)(q, radius_dofs) == expected


def test_a_kernel_without_a_python_entry_point_runs_as_python_when_python_calls_it(monkeypatch):
    """numba's dispatcher of a no_cpython_wrapper kernel crashes the process when called from
    Python; the Kernel runs its Python instead (and compiled callers still link it)."""
    import snapmem._lazy as lazy
    monkeypatch.setattr(lazy, "_seen", {})
    kernel = lazy.Kernel(lambda x: 2.0 * x, {"cache": False, "no_cpython_wrapper": True})
    assert kernel(1.5) == 3.0 and kernel._dispatcher is None
    pytest.importorskip("numba")
    namespace = {"twice": kernel}
    exec("def use(x):\n    return twice(x) + 1.0\n", namespace)
    compiled_caller = lazy.Kernel(namespace["use"], {"cache": False})
    assert compiled_caller.dispatcher(1.5) == 4.0          # links the compiled kernel
    assert kernel(2.0) == 4.0                                # Python still gets the Python
