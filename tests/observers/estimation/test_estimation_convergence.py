"""Convergence of the continuous estimators, checked against analytic results.

Signals are sampled at the start of each step and held over it (dt = 1e-3 s).
Times "by t = T" are stated with the measured time in a comment; tolerances
on analytic comparisons state where the difference comes from.
"""

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.linalg import expm
from scipy.optimize import brentq

from obsfmu.observers.checks import ParameterError
from obsfmu.observers.estimation import (
    DREM,
    DelayExtension,
    FilterBankExtension,
    FiniteTimeDREM,
    Gradient,
    KreisselmeierExtension,
    LeastSquaresForgetting,
)

DT = 1e-3
THETA = np.array([1.0, 2.0])


def pe_regressor(t):
    return np.array([np.sin(t), np.cos(t)])


def simulate(estimator, phi_of_t, T, theta=THETA, dt=DT):
    """Run ``estimator`` on ``y = phi(t)^T theta``; return end-of-step times and estimates."""
    steps = int(round(T / dt))
    estimates = np.empty((steps, theta.size))
    for k in range(steps):
        phi = phi_of_t(k * dt)
        estimates[k] = estimator.update(phi @ theta, phi, dt)
    return dt * np.arange(1, steps + 1), estimates


def first_time_below(times, errors, level):
    below = errors < level
    assert below[-1], f"error {errors[-1]:.3g} not below {level:g} at the end"
    return times[np.argmax(below)]


def stays_below_from(errors, level):
    """True when, once below ``level``, the error never goes back above it."""
    below = errors < level
    return bool(np.all(below[np.argmax(below):]))


# --- persistently exciting regressor phi = [sin t, cos t], theta = [1, 2] ------------------

def test_gradient_error_follows_the_analytic_solution_and_converges_exponentially():
    # With Q(t) = [[cos t, sin t], [-sin t, cos t]] (phi = Q e2), z = Q^T e obeys
    # z' = (J - gamma e2 e2^T) z: e(t) = Q(t) expm(A t) e(0), A = [[0, -1], [1, -gamma]].
    gamma = 2.0                                         # A has the double eigenvalue -1
    times, estimates = simulate(Gradient(2, gamma), pe_regressor, 18.0)
    A = np.array([[0.0, -1.0], [1.0, -gamma]])
    for T in (1.0, 3.0, 5.0, 8.0):
        Q = np.array([[np.cos(T), np.sin(T)], [-np.sin(T), np.cos(T)]])
        analytic = Q @ expm(A * T) @ THETA
        error = THETA - estimates[int(round(T / DT)) - 1]
        # holding phi over dt shifts it by dt/2 on average: measured 0.2-0.45 % (dt = 1e-3)
        assert np.linalg.norm(error - analytic) < 1e-2 * np.linalg.norm(analytic)
    errors = np.linalg.norm(estimates - THETA, axis=1)
    assert first_time_below(times, errors, 1e-6) <= 18.0          # measured 16.9 s
    assert stays_below_from(errors, 1e-6)


def test_normalised_gradient_is_the_gradient_with_gain_gamma_over_one_plus_phi_squared():
    _, plain = simulate(Gradient(2, 2.0), pe_regressor, 2.0)
    _, normalised = simulate(Gradient(2, 4.0, normalize=True), pe_regressor, 2.0)   # |phi| = 1
    np.testing.assert_allclose(normalised, plain, rtol=0, atol=1e-13)


def test_least_squares_with_forgetting_converges_with_the_paper_gains():
    est = LeastSquaresForgetting(2, gamma=1000.0, beta=1.0, f0=0.1, M=1e12)
    times, estimates = simulate(est, pe_regressor, 8.0)
    errors = np.linalg.norm(estimates - THETA, axis=1)
    assert first_time_below(times, errors, 1e-6) <= 7.0           # measured 6.46 s
    assert not est.frozen


def analytic_filter_delta(t):
    """Delta = det [phi; H phi] for phi = [sin t, cos t], H = 1/(p + 1), zero initial state."""
    return 0.5 * (1.0 - np.exp(-t) * (np.sin(t) + np.cos(t)))


def test_drem_error_decays_as_exp_of_minus_gamma_integral_delta_squared():
    gamma = 10.0
    est = DREM(FilterBankExtension([1.0]), gamma, normalize=False)
    times, estimates = simulate(est, pe_regressor, 8.0)
    for T in (2.0, 4.0, 6.0, 8.0):
        exponent = gamma * quad(lambda s: analytic_filter_delta(s) ** 2, 0.0, T, limit=200)[0]
        error = THETA - estimates[int(round(T / DT)) - 1]
        measured = -np.log(error / THETA)                  # the same for both parameters
        # held signals shift Delta by O(dt): relative rate error ~ dt (measured 1.000e-3)
        np.testing.assert_allclose(measured, exponent, rtol=2e-3)
    errors = np.linalg.norm(estimates - THETA, axis=1)
    assert first_time_below(times, errors, 1e-6) <= 7.5           # measured 7.09 s


@pytest.mark.parametrize("floor", [0.05, 0.5])
def test_drem_with_a_normalised_gain_decays_as_exp_of_minus_gamma_integral_of_delta2_over_floor2_plus_delta2(floor):
    """Gain gamma / (floor^2 + Delta^2): the rate is gamma where |Delta| >> floor, gamma Delta^2 / floor^2 below."""
    gamma = 10.0
    est = DREM(FilterBankExtension([1.0]), gamma, normalize=False, floor=floor)
    _, estimates = simulate(est, pe_regressor, 4.0)

    def rate(s):
        delta2 = analytic_filter_delta(s) ** 2
        return delta2 / (floor ** 2 + delta2)
    for T in (0.5, 1.0, 2.0):
        exponent = gamma * quad(rate, 0.0, T, limit=200)[0]
        measured = -np.log((THETA - estimates[int(round(T / DT)) - 1]) / THETA)
        np.testing.assert_allclose(measured, exponent, rtol=3e-3)     # held Delta: O(dt), measured < 1.6e-3


def test_drem_refuses_a_negative_or_nan_floor():
    for floor in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ParameterError, match="floor"):
            DREM(FilterBankExtension([1.0]), 1.0, floor=floor)


@pytest.mark.parametrize(
    "make_extension, deadline",
    [
        (lambda: FilterBankExtension([1.0]), 5.0),              # measured 4.31 s
        (lambda: KreisselmeierExtension(2, a=1.0), 4.5),        # measured 3.78 s
        (lambda: DelayExtension([500]), 7.5),                   # 0.5 s delay, measured 6.86 s
    ],
    ids=["filter-bank", "kreisselmeier", "delay"],
)
def test_normalised_drem_converges_with_every_extension(make_extension, deadline):
    times, estimates = simulate(DREM(make_extension(), 10.0), pe_regressor, deadline + 0.5)
    errors = np.linalg.norm(estimates - THETA, axis=1)
    assert first_time_below(times, errors, 1e-6) <= deadline
    assert stays_below_from(errors, 1e-6)


def two_row_regressor(t):
    return np.array([[np.sin(t), np.cos(t), np.sin(2 * t), np.cos(2 * t)],
                     [np.cos(2 * t), -np.sin(2 * t), np.cos(t), -np.sin(t)]])


@pytest.mark.parametrize(
    "make_estimator, deadline",
    [
        (lambda: Gradient(4, 0.7), 27.0),                                  # measured 25.3 s
        (lambda: LeastSquaresForgetting(4, 1000.0, 1.0, 0.1, 1e12), 6.5),  # measured 5.58 s
        (lambda: DREM(FilterBankExtension([1.0], rows=2), 50.0), 3.0),     # measured 2.20 s
        (lambda: DREM(KreisselmeierExtension(4, a=1.0), 50.0), 3.0),       # measured 2.27 s
    ],
    ids=["gradient", "least-squares", "drem-filter-bank", "drem-kreisselmeier"],
)
def test_vector_regression_with_two_rows(make_estimator, deadline):
    theta = np.array([1.0, 2.0, -1.0, 0.5])
    times, estimates = simulate(make_estimator(), two_row_regressor, deadline + 0.5, theta=theta)
    errors = np.max(np.abs(estimates - theta), axis=1)
    assert first_time_below(times, errors, 1e-6) <= deadline


# --- regressor not PE, Delta not square-integrable ----------------------------------------

def not_pe_regressor(t):
    return np.array([1.0, 1.0 / (1.0 + t)])


def test_example_regressor_is_not_persistently_exciting():
    # smallest eigenvalue of int_t^{t+1} phi phi^T -> 0 (like t^-4): no PE window exists
    def window_min_eig(t):
        entries = [quad(lambda s, i=i, j=j: not_pe_regressor(s)[i] * not_pe_regressor(s)[j], t, t + 1)[0]
                   for i, j in ((0, 0), (0, 1), (1, 1))]
        return np.linalg.eigvalsh([[entries[0], entries[1]], [entries[1], entries[2]]])[0]

    values = [window_min_eig(t) for t in (10.0, 100.0, 1000.0)]
    assert values[0] > values[1] > values[2] and values[2] < 1e-12


def test_gradient_stalls_where_the_regressor_is_not_pe():
    # e2' = -gamma phi2 (phi^T e) and int (phi^T e)^2 <= |e(0)|^2 / (2 gamma) (V = |e|^2) give
    # |e2(t) - e2(0)| <= sqrt(gamma/2 int phi2^2) |e(0)|: e2 cannot reach 0 when that is < |e2(0)|.
    gamma, T = 1.0, 20.0
    times, estimates = simulate(Gradient(2, gamma), not_pe_regressor, T)
    sampled_phi2 = 1.0 / (1.0 + DT * np.arange(times.size))
    bound = abs(THETA[1]) - np.sqrt(gamma / 2 * DT * np.sum(sampled_phi2**2)) * np.linalg.norm(THETA)
    assert bound > 0.4                                          # 0.438: a proof of stalling
    assert np.all(np.abs(estimates[:, 1] - THETA[1]) >= bound)  # measured 1.06 at t = 20 s


def test_drem_with_integral_extension_converges_where_the_gradient_stalls():
    # Phi_e = int phi phi^T (a = 0): Delta = t^2/(1+t) - log(1+t)^2 ~ t, not square-integrable
    est = DREM(KreisselmeierExtension(2, a=0.0), 1.0, normalize=False)
    times, estimates = simulate(est, not_pe_regressor, 12.0)
    analytic_delta = 12.0**2 / 13.0 - np.log(13.0) ** 2
    assert est.delta == pytest.approx(analytic_delta, rel=1e-3)     # held signals: O(dt)
    errors = np.linalg.norm(estimates - THETA, axis=1)
    assert first_time_below(times, errors, 1e-6) <= 10.0            # measured 8.89 s
    assert errors[-1] < 1e-9


# --- finite-time DREM ---------------------------------------------------------------------

def test_finite_time_drem_is_exact_from_the_moment_nu_drops_below_mu():
    gamma, mu = 10.0, 0.5
    ft = FiniteTimeDREM(FilterBankExtension([1.0]), gamma, mu, normalize=False)
    drem = DREM(FilterBankExtension([1.0]), gamma, normalize=False)
    times, ft_estimates = simulate(ft, pe_regressor, 3.0)
    _, drem_estimates = simulate(drem, pe_regressor, 3.0)
    # analytic switch time: gamma int_0^t Delta^2 = ln(1/mu)
    exponent = lambda T: gamma * quad(lambda s: analytic_filter_delta(s) ** 2, 0.0, T)[0]
    analytic_switch = brentq(lambda T: exponent(T) - np.log(1.0 / mu), 0.1, 3.0)
    assert ft.converged
    assert ft.switch_time == pytest.approx(analytic_switch, abs=5 * DT)   # 1.5171 s; measured 1.5170 s
    switch = int(round(ft.switch_time / DT)) - 1
    ft_errors = np.max(np.abs(ft_estimates - THETA), axis=1)
    drem_errors = np.max(np.abs(drem_estimates - THETA), axis=1)
    assert np.all(ft_errors[switch:] < 1e-9)                  # exact from the switch on
    assert np.all(ft_errors[:switch] > 1e-3)                  # and not before
    assert drem_errors[switch] > 0.4 * np.max(THETA)          # DREM still at ~mu |error(0)|
    assert drem_errors[-1] > 1e-3                             # and still converging at 3 s
    np.testing.assert_allclose(ft.nu, np.exp(-exponent(3.0)), rtol=5e-3)


def test_finite_time_drem_with_paper_003_gains_is_stable_and_exact():
    # gamma = 1e6, mu = 0.98 (paper 003): gamma Delta^2 dt reaches ~250 per step
    ft = FiniteTimeDREM(FilterBankExtension([10.0]), 1e6, 0.98, normalize=False)
    drem = DREM(FilterBankExtension([10.0]), 1e10, normalize=False)
    _, ft_estimates = simulate(ft, pe_regressor, 0.5)
    _, drem_estimates = simulate(drem, pe_regressor, 0.5)
    assert ft.converged and ft.switch_time < 0.05          # measured 0.022 s
    switch = int(round(ft.switch_time / DT)) - 1
    assert np.max(np.abs(ft_estimates[switch:] - THETA)) < 1e-9
    assert np.all(np.isfinite(drem_estimates))
    assert np.max(np.abs(drem_estimates[-1] - THETA)) < 1e-12
