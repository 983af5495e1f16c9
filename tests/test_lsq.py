"""boucwen.lsq, the output-error engine of fit and fit_extended, on problems whose
answer is known in closed form."""

import numpy as np
import pytest

from boucwen.levenberg import STATISTICAL_MARGIN, levenberg_marquardt
from boucwen.lsq import (
    FAIL_RESIDUAL_UM,
    OutputErrorProblem,
    Ridge,
    finite_or_none,
    orthonormal,
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
    return M @ z, M.copy()


def test_residual_and_jacobian_of_a_linear_model():
    prob = OutputErrorProblem(_linear, _linear_with_jacobian, TARGET)
    z = np.array([0.3, 0.2, -0.1])
    np.testing.assert_array_equal(prob.jacobian(z), M)
    np.testing.assert_allclose(prob.residual(z), M @ z - TARGET, rtol=0, atol=1e-15)
    # one simulation with the Jacobian, one for the residual
    assert prob.simulations == 2


def _mahalanobis2(z, want):
    """(z − want)ᵀ·MᵀM·(z − want) / σ̂²: the squared distance in standard errors."""
    resid = M @ want - TARGET
    sigma2 = float(resid @ resid) / (M.shape[0] - M.shape[1])
    d = z - want
    return float(d @ (M.T @ M) @ d) / sigma2


def test_solve_stops_within_the_statistical_margin_of_the_answer():
    want, *_ = np.linalg.lstsq(M, TARGET, rcond=None)
    lower, upper = np.full(3, -np.inf), np.full(3, np.inf)
    prob = OutputErrorProblem(_linear, _linear_with_jacobian, TARGET)
    res = prob.solve(np.zeros(3), lower, upper, x_scale=1.0, tol=1e-15, max_nfev=50)
    assert res.success and "statistical margin" in res.message
    assert _mahalanobis2(res.x, want) <= STATISTICAL_MARGIN
    # A linear model's Jacobian predicts every step exactly: kept, it is the one pass.
    kept = prob.solve(np.zeros(3), lower, upper, x_scale=1.0, tol=1e-15, max_nfev=50, reuse_jacobian=True)
    assert kept.njev == 1 and _mahalanobis2(kept.x, want) <= STATISTICAL_MARGIN
    exact = OutputErrorProblem(_linear, _linear_with_jacobian, TARGET)
    res = exact.solve(np.zeros(3), lower, upper, x_scale=1.0, tol=1e-15, max_nfev=50, margin=0.0)
    np.testing.assert_allclose(res.x, want, rtol=0, atol=1e-8)
    assert exact.cost(res.x) == pytest.approx(float(np.sum((M @ want - TARGET) ** 2)), rel=1e-9)


def test_solve_holds_an_unknown_at_the_bound_its_step_leaves():
    # The unconstrained answer has z[1] ≈ −2; with z[1] ≥ −1 the answer holds it at −1
    # and fits the other two: the least squares of TARGET + M[:, 1] on columns 0 and 2.
    lower = np.array([-np.inf, -1.0, -np.inf])
    upper = np.full(3, np.inf)
    prob = OutputErrorProblem(_linear, _linear_with_jacobian, TARGET)
    res = prob.solve(np.zeros(3), lower, upper, x_scale=1.0, tol=1e-15, max_nfev=100, margin=0.0)
    assert res.x[1] == pytest.approx(-1.0, abs=1e-9)
    rest, *_ = np.linalg.lstsq(M[:, [0, 2]], TARGET + M[:, 1], rcond=None)
    np.testing.assert_allclose(res.x[[0, 2]], rest, rtol=0, atol=1e-7)


def test_solve_from_a_start_that_cannot_be_simulated():
    prob = OutputErrorProblem(lambda z: None, lambda z: None, TARGET)
    res = prob.solve(np.zeros(3), np.full(3, -np.inf), np.full(3, np.inf), x_scale=1.0, tol=1e-8, max_nfev=5)
    assert not res.success and "cannot be simulated" in res.message


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


def test_orthonormal_spans_the_basis():
    u = np.linspace(0.0, 100.0, 5000) ** 1.3
    basis = np.column_stack([u, np.ones_like(u), np.sin(u)])
    q = orthonormal(basis)
    np.testing.assert_allclose(q.T @ q, np.eye(3), rtol=0, atol=1e-13)
    # The same span: projecting the basis onto it leaves it unchanged.
    np.testing.assert_allclose(q @ (q.T @ basis), basis, rtol=0, atol=1e-9 * float(np.abs(basis).max()))


def test_a_jacobian_whose_normal_equations_overflow_stops_the_solver():
    # Finite entries whose squares overflow (a model driven far out): no step is solved
    # from them, and the solver says why instead of failing inside the eigensolver.
    def linearise(z):
        return np.array([1.0]), np.array([[1e200]])

    res = levenberg_marquardt(
        lambda z: np.array([1.0]),
        linearise,
        np.array([1.0]),
        np.array([-np.inf]),
        np.array([np.inf]),
        x_scale=1.0,
        tol=1e-10,
        max_nfev=10,
    )
    assert not res.success and res.message == "the start cannot be linearised"
