"""boucwen.lsq, the output-error engine of fit and fit_extended, on problems whose
answer is known in closed form."""

import numpy as np
import pytest

from boucwen.lsq import (
    FAIL_RESIDUAL_UM,
    OutputErrorProblem,
    Ridge,
    finite_or_none,
    with_jacobian_or_none,
    worker_threads,
)

RNG = np.random.default_rng(7)
# A linear "simulator" s(z) = M·z, whose Jacobian is M.
M = RNG.normal(size=(40, 3))
TARGET = M @ np.array([1.0, -2.0, 0.5]) + 0.01 * RNG.normal(size=40)


def _linear(z):
    return M @ z


def _linear_with_jacobian(z):
    return M @ z, M


def test_residual_and_jacobian_of_a_linear_model():
    prob = OutputErrorProblem(_linear, _linear_with_jacobian, TARGET)
    z = np.array([0.3, 0.2, -0.1])
    np.testing.assert_array_equal(prob.jacobian(z), M)
    np.testing.assert_allclose(prob.residual(z), M @ z - TARGET, rtol=0, atol=1e-15)
    # one simulation with the Jacobian, one for the residual
    assert prob.simulations == 2


def test_solve_finds_the_linear_least_squares_answer():
    prob = OutputErrorProblem(_linear, _linear_with_jacobian, TARGET)
    lower, upper = np.full(3, -np.inf), np.full(3, np.inf)
    res = prob.solve(np.zeros(3), lower, upper, x_scale=1.0, tol=1e-12, max_nfev=50)
    want, *_ = np.linalg.lstsq(M, TARGET, rcond=None)
    np.testing.assert_allclose(res.x, want, rtol=0, atol=1e-8)
    assert prob.cost(res.x) == pytest.approx(float(np.sum((M @ want - TARGET) ** 2)), rel=1e-9)


def test_projection_and_ridge_rows():
    basis = np.column_stack([np.ones(40), np.arange(40.0)])
    q, _ = np.linalg.qr(basis)
    ridge = Ridge(index=1, weight=1e-3, scale=2.0)
    prob = OutputErrorProblem(_linear, _linear_with_jacobian, TARGET, basis=basis, ridge=ridge)
    z = np.array([0.3, 0.2, -0.1])
    r = prob.residual(z)
    raw = M @ z - TARGET
    np.testing.assert_allclose(r[:-1], raw - q @ (q.T @ raw), rtol=0, atol=1e-12)
    assert r[-1] == pytest.approx(1e-3 * 0.2 * 2.0)
    jac = prob.jacobian(z)
    np.testing.assert_allclose(jac[:-1], M - q @ (q.T @ M), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(jac[-1], [0.0, 1e-3 * 2.0, 0.0])


def test_a_point_that_cannot_be_simulated():
    prob = OutputErrorProblem(lambda z: None, lambda z: None, TARGET, ridge=Ridge(0, 1.0, 1.0))
    z = np.zeros(3)
    np.testing.assert_array_equal(prob.residual(z), np.full(41, FAIL_RESIDUAL_UM))
    np.testing.assert_array_equal(prob.jacobian(z), np.zeros((41, 3)))


def _cannot_simulate():
    raise ValueError("no such parameter set")


def test_finite_or_none_and_workers():
    np.testing.assert_array_equal(finite_or_none(lambda: [1.0, 2.0]), [1.0, 2.0])
    assert finite_or_none(lambda: [1.0, np.nan]) is None
    assert finite_or_none(_cannot_simulate) is None
    assert with_jacobian_or_none(lambda: ([1.0], [[np.inf]])) is None
    assert with_jacobian_or_none(_cannot_simulate) is None
    s, jac = with_jacobian_or_none(lambda: ([1.0], [[2.0]]))
    assert s.tolist() == [1.0] and jac.tolist() == [[2.0]]
    with pytest.raises(ValueError, match="workers"), worker_threads(0):
        pass
