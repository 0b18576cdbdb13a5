"""LeastSquaresForgetting (paper 001) against Radau references and the analytic Riccati solution."""

import functools

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from obsfmu.observers.estimation import LeastSquaresForgetting

# paper 001's estimator gains
GAMMA, BETA, f0, M = 1000.0, 1.0, 0.1, 1e12  # F(0) = I / f0
THETA = np.array([1.0, 2.0, -1.0])
P = THETA.size
DT = 1e-3


def regressor(t):
    return np.array([np.sin(t), np.cos(t), 1.0])


def paper_law(phi, y):
    """Right-hand side of paper 001's law in the original (theta, F) coordinates (bound inactive)."""
    def rhs(t, state):
        theta, F = state[:P], state[P:].reshape(P, P)
        F_phi = F @ phi
        return np.concatenate((GAMMA * F_phi * (y - phi @ theta),
                               (-GAMMA * np.outer(F_phi, F_phi) + BETA * F).ravel()))
    return rhs


def initial_state():
    return np.concatenate((np.zeros(P), (np.eye(P) / f0).ravel()))


def test_exact_step_equals_radau_for_the_same_held_signals():
    # Radau (rtol 1e-12) on each step with phi, y held; 1 s covers the stiff start (rate ~1e4 1/s)
    est = LeastSquaresForgetting(P, GAMMA, BETA, f0, M)
    state = initial_state()
    theta_errors, F_errors = [], []
    for k in range(1000):
        phi = regressor(k * DT)
        y = phi @ THETA
        state = solve_ivp(paper_law(phi, y), (0.0, DT), state, method="Radau", rtol=1e-12, atol=1e-14).y[:, -1]
        theta_errors.append(np.max(np.abs(est.update(y, phi, DT) - state[:P])))
        F_reference = state[P:].reshape(P, P)
        F_errors.append(np.max(np.abs(est.F - F_reference)) / np.max(np.abs(F_reference)))
    assert max(theta_errors) < 1e-9            # measured 9.8e-13
    assert max(F_errors) < 1e-9                # measured 7.2e-12 (relative)
    assert not est.frozen


@functools.lru_cache(maxsize=1)
def continuous_reference(steps=2000):
    """Radau on the continuous signals phi(t), estimates at the step ends DT, 2 DT, ..."""
    def rhs(t, state):
        phi = regressor(t)
        return paper_law(phi, phi @ THETA)(t, state)

    times = DT * np.arange(1, steps + 1)
    return solve_ivp(rhs, (0.0, times[-1]), initial_state(), method="Radau",
                     rtol=1e-12, atol=1e-14, t_eval=times).y[:P].T


@pytest.mark.parametrize("sample_at, tolerance", [(0.0, 1e-3), (0.5, 5e-5)], ids=["start", "midpoint"])
def test_hold_error_against_radau_on_the_continuous_signals(sample_at, tolerance):
    # continuous phi(t): the only difference is holding phi over the step (first order in dt,
    # second order when sampled at the midpoint).  Measured: 7.5e-4 (start), 3.4e-5 (midpoint).
    reference = continuous_reference()
    est = LeastSquaresForgetting(P, GAMMA, BETA, f0, M)
    estimates = []
    for k in range(len(reference)):
        phi = regressor((k + sample_at) * DT)
        estimates.append(est.update(phi @ THETA, phi, DT))
    assert np.max(np.abs(np.array(estimates) - reference)) < tolerance


@pytest.mark.parametrize("dt", [1e-3, 0.05])
def test_constant_regressor_matches_the_analytic_riccati_solution_for_any_step(dt):
    # phi = [1, 0], F(0) = I/f0: F11' = -gamma F11^2 + beta F11 (logistic) gives
    # F11 = beta / (gamma + c e^{-beta t}) with c = beta f0 - gamma, F22 = e^{beta t} / f0, and
    # theta1_tilde' = -gamma F11 theta1_tilde gives theta1_tilde = theta1_tilde(0) beta f0 / (gamma e^{beta t} + c).
    est = LeastSquaresForgetting(2, GAMMA, BETA, f0, M)
    phi, theta = np.array([1.0, 0.0]), np.array([3.0, -1.0])
    c = BETA * f0 - GAMMA
    for k in range(1, int(round(2.0 / dt)) + 1):
        est.update(phi @ theta, phi, dt)
        t = k * dt
        F = est.F
        assert F[0, 0] == pytest.approx(BETA / (GAMMA + c * np.exp(-BETA * t)), rel=1e-12)
        assert F[1, 1] == pytest.approx(np.exp(BETA * t) / f0, rel=1e-12)
        assert abs(F[0, 1]) < 1e-12
        expected_error = theta[0] * BETA * f0 / (GAMMA * np.exp(BETA * t) + c)
        assert theta[0] - est.theta_hat[0] == pytest.approx(expected_error, rel=1e-9, abs=1e-15)
        assert est.theta_hat[1] == 0.0                     # never excited


def test_gain_freezes_once_its_largest_eigenvalue_exceeds_the_bound():
    # phi = [1, 0], f0 = 0.1: F22 = 10 e^t crosses M = 20 at t = ln 2; from the next step on F' = 0
    dt, bound = 1e-3, 20.0
    est = LeastSquaresForgetting(2, GAMMA, BETA, f0, bound)
    phi, theta = np.array([1.0, 0.0]), np.array([3.0, -1.0])
    freeze_step = int(np.floor(np.log(2.0) / dt)) + 1       # first step starting with F22 > 20
    for k in range(3000):
        est.update(phi @ theta, phi, dt)
        assert est.frozen == (k >= freeze_step)
    F = est.F
    assert F[1, 1] == pytest.approx(np.exp(freeze_step * dt) / f0, rel=1e-12)
    assert bound < F[1, 1] <= bound * np.exp(BETA * dt)
    c = BETA * f0 - GAMMA
    F11 = BETA / (GAMMA + c * np.exp(-BETA * freeze_step * dt))
    assert F[0, 0] == pytest.approx(F11, rel=1e-12)
    # frozen F: theta1_tilde decays with the constant rate gamma F11
    frozen_error = theta[0] * BETA * f0 / (GAMMA * np.exp(BETA * freeze_step * dt) + c)
    expected = frozen_error * np.exp(-GAMMA * F11 * (3000 - freeze_step) * dt)
    assert theta[0] - est.theta_hat[0] == pytest.approx(expected, rel=1e-9)
