import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import lsq_linear

from engine.errors import InputError
from engine.figurate import outside_matrix, transport_matrix
from engine.solve import ConeSolver, Constraint, cone_basis


def _noisy_columns(order, count, rng, noise=0.01):
    comps = np.sort(rng.random((order, count)), axis=0)[::-1] * (0.35 ** np.arange(order))[:, None]
    b = transport_matrix(order) @ comps
    return b + rng.normal(0.0, noise, b.shape) * b[0]


def _reference(a, basis, b):
    """scipy's bounded least squares on the reparametrised problem, one column at a time."""
    g = a @ basis
    out = np.empty((a.shape[1], b.shape[1]))
    for j in range(b.shape[1]):
        d = lsq_linear(g, b[:, j], bounds=(0, np.inf), method="bvls", tol=1e-14).x
        out[:, j] = basis @ d
    return out


@pytest.mark.parametrize("order", [2, 3, 4, 5, 6])
@pytest.mark.parametrize("constraint", ["ordered", "nonnegative"])
@pytest.mark.parametrize("outside", [False, True])
def test_agrees_with_scipy_on_noisy_pixels(order, constraint, outside):
    rng = np.random.default_rng(order)
    b = _noisy_columns(order, 1500, rng)
    a = outside_matrix(order) if outside else transport_matrix(order)
    basis = cone_basis(order, constraint, leading_free=outside)
    ours = ConeSolver(a, basis).solve(b)
    ref = _reference(a, basis, b[:, :300])
    scale = np.abs(b[:, :300]).max(axis=0)
    assert np.max(np.abs(ours[:, :300] - ref) / scale) < 1e-7
    # the result is feasible: x = P d with d >= 0
    d = np.linalg.solve(basis, ours)
    assert d.min() >= -1e-9 * np.abs(b).max()


@pytest.mark.parametrize("order", [3, 5])
def test_float32_agrees_with_scipy(order):
    rng = np.random.default_rng(7)
    b = _noisy_columns(order, 400, rng).astype(np.float32)
    a, basis = transport_matrix(order), cone_basis(order, "ordered")
    ours = ConeSolver(a, basis).solve(b)
    assert ours.dtype == np.float32
    ref = _reference(a, basis, b.astype(np.float64))
    assert np.max(np.abs(ours - ref) / np.abs(b).max(axis=0)) < 2e-5


def test_unconstrained_is_the_linear_solve():
    rng = np.random.default_rng(1)
    b = rng.normal(size=(4, 50))
    x = ConeSolver(transport_matrix(4), cone_basis(4, "none")).solve(b)
    np.testing.assert_allclose(transport_matrix(4) @ x, b, atol=1e-10)


def test_ordered_solution_is_monotone_and_nonnegative():
    rng = np.random.default_rng(2)
    b = rng.normal(size=(5, 2000))  # arbitrary, mostly infeasible data
    x = ConeSolver(transport_matrix(5), cone_basis(5, "ordered")).solve(b)
    tol = 1e-9 * np.abs(b).max()
    assert (x[-1] >= -tol).all()
    assert (np.diff(x, axis=0) <= tol).all()


def test_zero_columns_give_zero():
    x = ConeSolver(transport_matrix(3), cone_basis(3, "ordered")).solve(np.zeros((3, 10), np.float32))
    assert not x.any()


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-1, 1), min_size=4, max_size=4), st.integers(0, 2**32 - 1))
def test_no_feasible_point_does_better(values, seed):
    a, basis = transport_matrix(4), cone_basis(4, "ordered")
    b = np.array(values)[:, None]
    x = ConeSolver(a, basis).solve(b)[:, 0]
    best = np.linalg.norm(a @ x - b[:, 0])
    rng = np.random.default_rng(seed)
    for d in rng.random((200, 4)) * rng.random((200, 1)) * 2:
        assert np.linalg.norm(a @ (basis @ d) - b[:, 0]) >= best - 1e-9


def test_constraint_names():
    assert [c.value for c in Constraint] == ["ordered", "nonnegative", "none"]
    with pytest.raises(InputError, match="constraint must be one of"):
        cone_basis(3, "positive")


def test_rank_deficient_system_is_refused():
    with pytest.raises(InputError, match="full column rank"):
        ConeSolver(np.ones((3, 3)), np.eye(3))


def test_concurrent_solves_from_threads_agree():
    from concurrent.futures import ThreadPoolExecutor

    rng = np.random.default_rng(3)
    b = _noisy_columns(5, 20000, rng).astype(np.float32)
    solver = ConeSolver(transport_matrix(5), cone_basis(5, "ordered"))
    expected = solver.solve(b)
    with ThreadPoolExecutor(4) as pool:
        results = list(pool.map(lambda _: solver.solve(b), range(8)))
    for r in results:
        np.testing.assert_array_equal(r, expected)
