"""observers.riccati: Newton's method for the Riccati equations (numpy only, what an FMU runs at initialisation)
against SciPy's Schur-method solvers, from any stabilising start; bad weights and unstabilising starts named."""

import numpy as np
import pytest
from scipy.linalg import solve_continuous_are, solve_discrete_are

from obsfmu.observers.checks import ParameterError
from obsfmu.observers.modal import place
from obsfmu.observers.riccati import checked_weight, dkalman_newton, dlqr_newton, kalman_newton, lqr_newton


def problems(count: int, discrete: bool):
    rng = np.random.default_rng(1)
    for _ in range(count):
        n, m = int(rng.integers(2, 7)), int(rng.integers(1, 3))
        A = rng.standard_normal((n, n)) * (0.4 if discrete else 1.0)
        B = rng.standard_normal((n, m))
        G = rng.standard_normal((n, n))
        yield A, B, G @ G.T + 1e-3 * np.eye(n), np.diag(rng.uniform(0.1, 2.0, m))


@pytest.mark.parametrize("discrete", [False, True])
def test_newton_converges_to_scipys_stabilising_solution(discrete):
    """From a pole-placement start far from the optimum, 20 random plants each: the gain equals SciPy's to 1e-9
    (relative to its largest entry)."""
    for A, B, Q, R in problems(20, discrete):
        n = len(A)
        poles = np.linspace(0.2, 0.6, n) if discrete else -np.linspace(1.0, 3.0, n)
        K0 = place(A, B, poles)
        if discrete:
            P = solve_discrete_are(A, B, Q, R)
            expected = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
            K = dlqr_newton(A, B, Q, R, K0)
        else:
            expected = np.linalg.solve(R, B.T @ solve_continuous_are(A, B, Q, R))
            K = lqr_newton(A, B, Q, R, K0)
        np.testing.assert_allclose(K, expected, rtol=0, atol=1e-9 * np.abs(expected).max())


def test_the_kalman_gains_are_the_duals():
    A, C = np.array([[0.0, 1.0], [-2.0, -3.0]]), np.array([[1.0, 0.0]])
    Q, R = np.diag([0.1, 1.0]), np.array([[0.01]])
    P = solve_continuous_are(A.T, C.T, Q, R)
    np.testing.assert_allclose(kalman_newton(A, C, Q, R, np.array([[5.0], [5.0]])), P @ C.T / 0.01, rtol=1e-10)
    Ad = np.array([[1.0, 0.1], [-0.2, 0.9]])
    P = solve_discrete_are(Ad.T, C.T, Q, R)
    expected = Ad @ P @ C.T @ np.linalg.inv(C @ P @ C.T + R)
    np.testing.assert_allclose(dkalman_newton(Ad, C, Q, R, np.array([[1.0], [0.5]])), expected, rtol=1e-10)


def test_a_start_that_does_not_stabilise_is_refused():
    A, B = np.array([[1.0, 0.0], [0.0, 2.0]]), np.eye(2)
    with pytest.raises(ParameterError, match="Q, R: the Riccati iteration lost stability"):
        lqr_newton(A, B, np.eye(2), np.eye(2), np.zeros((2, 2)))


@pytest.mark.parametrize("value, definite, message", [
    (np.ones((2, 3)), True, "R: expected a 2 x 2 matrix, got 2 x 3"),
    ([[1.0, 0.0], [0.0, np.nan]], True, "R: a covariance must be finite"),
    ([[1.0, 0.5], [0.0, 1.0]], True, "R: a covariance must be symmetric"),
    ([[1.0, 0.0], [0.0, 0.0]], True, r"R: a covariance must be positive definite \(smallest eigenvalue 0\)"),
    ([[1.0, 0.0], [0.0, -1.0]], False, "R: a covariance must be positive semidefinite"),
])
def test_bad_weights_are_named(value, definite, message):
    with pytest.raises(ParameterError, match=message):
        checked_weight("R", value, 2, definite)
