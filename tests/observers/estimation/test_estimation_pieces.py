"""Building blocks of observers.estimation against analytic or scipy references."""

import itertools

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.signal import lsim

from obsfmu.observers.checks import SignalError
from obsfmu.observers.estimation import (
    DelayExtension,
    FilterBankExtension,
    KreisselmeierExtension,
    discrete_scalar_gradient_step,
    finite_time_estimate,
    held_input_lowpass,
    mix,
    phi1,
    phi1_symmetric,
    scalar_gradient_step,
)


# --- phi1 ------------------------------------------------------------------------------

def _phi1_reference(x: float) -> float:
    """Taylor series below 1e-3 (truncation < 1e-13), the direct formula above (cancellation < 1e-13)."""
    if x < 1e-3:
        return 1.0 - x / 2.0 + x * x / 6.0 - x**3 / 24.0
    return (1.0 - np.exp(-x)) / x


@pytest.mark.parametrize("x", [0.0, 1e-300, 1e-12, 1e-6, 1e-3, 0.1, 1.0, 30.0, 1e3, 1e7, 1e10])
def test_phi1_matches_series_and_direct_formula(x):
    reference = 1.0 if x == 0.0 else _phi1_reference(x)
    assert phi1(x) == pytest.approx(reference, rel=1e-12)
    assert phi1(np.array([x]))[0] == pytest.approx(reference, rel=1e-12)


def test_phi1_symmetric_equals_inverse_formula_and_handles_singular_matrices():
    rng = np.random.default_rng(3)
    root = rng.normal(size=(4, 4))
    S = root @ root.T + 0.1 * np.eye(4)                    # SPD: S^-1 (I - e^-S) is defined
    reference = np.linalg.solve(S, np.eye(4) - expm(-S))
    np.testing.assert_allclose(phi1_symmetric(S), reference, rtol=1e-12, atol=1e-14)
    # rank one v v^T: phi1 = I + (phi1(|v|^2) - 1) v v^T / |v|^2 (analytic)
    v = np.array([1.0, -2.0, 0.5, 3.0])
    n2 = v @ v
    expected = np.eye(4) + (_phi1_reference(n2) - 1.0) * np.outer(v, v) / n2
    np.testing.assert_allclose(phi1_symmetric(np.outer(v, v)), expected, rtol=1e-12, atol=1e-14)


# --- exact filters ---------------------------------------------------------------------

def test_held_input_lowpass_equals_scipy_zero_order_hold_simulation():
    a, dt = 3.0, 0.05
    t = np.arange(200) * dt
    u = np.sin(2.0 * t) + 0.3 * np.cos(7.0 * t)
    _, reference, _ = lsim(([a], [1.0, a]), u, t, interp=False)  # a / (s + a), input held
    x, ours = 0.0, [0.0]
    for value in u[:-1]:
        x = held_input_lowpass(x, a * value, a, dt)
        ours.append(x)
    np.testing.assert_allclose(ours, reference, rtol=0, atol=1e-12)


def test_filter_bank_states_equal_scipy_and_keep_the_regression_exact():
    theta = np.array([1.0, 2.0, -0.5])
    bank = FilterBankExtension([1.0, 4.0])
    dt = 0.01
    t = np.arange(600) * dt
    phis = np.column_stack((np.sin(t), np.cos(3 * t), 1.0 + 0.2 * t))
    second_filter_on_first_entry = []
    for phi in phis:
        Y, Phi = np.array([phi @ theta]), phi[None, :]
        Y_e, Phi_e = bank.extend(Y, Phi)
        np.testing.assert_allclose(Y_e, Phi_e @ theta, rtol=0, atol=1e-12)
        second_filter_on_first_entry.append(Phi_e[2, 0])
        bank.advance(Y, Phi, dt)
    _, reference, _ = lsim(([4.0], [1.0, 4.0]), phis[:, 0], t, interp=False)  # 4/(s+4), held input
    np.testing.assert_allclose(second_filter_on_first_entry, reference, rtol=0, atol=1e-12)


def test_integral_kreisselmeier_extension_is_the_exact_sum_of_held_inputs():
    ext = KreisselmeierExtension(2, a=0.0)
    dt, total = 0.1, np.zeros((2, 2))
    for k in range(50):
        phi = np.array([[1.0, 1.0 / (1.0 + k * dt)]])
        ext.advance(phi @ np.array([1.0, 2.0]), phi, dt)
        total += dt * phi.T @ phi
    np.testing.assert_allclose(ext.Phi_e, total, rtol=1e-13)
    np.testing.assert_allclose(ext.Y_e, total @ [1.0, 2.0], rtol=1e-13)


def test_delay_extension_stacks_past_samples_and_zeros_before_start():
    ext = DelayExtension([1, 3])
    samples = [np.array([[float(k), 10.0 + k, 20.0 + k]]) for k in range(5)]
    stacked = []
    for phi in samples:
        stacked.append(ext.extend(np.array([phi[0, 0]]), phi)[1])
        ext.advance(np.array([phi[0, 0]]), phi)
    np.testing.assert_array_equal(stacked[0][1:], 0.0)
    np.testing.assert_array_equal(stacked[4], np.vstack((samples[4], samples[3], samples[1])))


# --- mixing ----------------------------------------------------------------------------

def _adjugate_by_cofactors(A):
    """Textbook adjugate: transpose of the cofactor matrix (independent of mix)."""
    n = A.shape[0]
    cof = np.empty_like(A)
    for i, j in itertools.product(range(n), range(n)):
        minor = np.delete(np.delete(A, i, axis=0), j, axis=1)
        cof[i, j] = (-1) ** (i + j) * np.linalg.det(minor)
    return cof.T


def test_mix_equals_determinant_and_adjugate_for_regular_and_singular_matrices():
    rng = np.random.default_rng(7)
    A = rng.normal(size=(5, 5))
    b = rng.normal(size=5)
    Y, delta = mix(b, A, normalize=False)
    assert delta == pytest.approx(np.linalg.det(A), rel=1e-12)
    np.testing.assert_allclose(Y, delta * np.linalg.solve(A, b), rtol=1e-10)
    singular = A.copy()
    singular[4] = singular[0] + 2.0 * singular[1]           # rank 4: no inverse, adjugate rank 1
    Y, delta = mix(b, singular, normalize=False)
    assert abs(delta) < 1e-12
    np.testing.assert_allclose(Y, _adjugate_by_cofactors(singular) @ b, rtol=1e-9, atol=1e-12)


def test_normalised_mixing_keeps_the_solution_and_bounds_delta():
    rng = np.random.default_rng(11)
    A = rng.normal(size=(6, 6)) * rng.uniform(0.01, 100.0, size=(6, 1))  # rows of very different size
    theta = rng.normal(size=6)
    Y, delta = mix(A @ theta, A, normalize=True)
    assert 0.0 < abs(delta) <= 1.0                          # Hadamard's inequality
    np.testing.assert_allclose(Y / delta, theta, rtol=1e-9)


def test_p10_normalised_mixing_is_scale_free_where_raw_mixing_under_or_overflows():
    rng = np.random.default_rng(5)
    A = rng.uniform(-1.0, 1.0, size=(10, 10))
    theta = rng.uniform(-2.0, 2.0, size=10)
    Y1, delta1 = mix(A @ theta, A)
    for scale in (1e-40, 1e40):
        Y, delta = mix(scale * A @ theta, scale * A)
        assert delta == pytest.approx(delta1, rel=1e-12)
        np.testing.assert_allclose(Y, Y1, rtol=1e-9)
    assert mix(1e-40 * A @ theta, 1e-40 * A, normalize=False)[1] == 0.0   # det ~ 1e-400 underflows
    with pytest.raises(SignalError, match="Delta"):
        mix(1e40 * A @ theta, 1e40 * A, normalize=False)                  # det ~ 1e400 overflows


# --- scalar laws -----------------------------------------------------------------------

@pytest.mark.parametrize(
    "gamma, delta, dt",
    [(1.0, 0.7, 0.01), (1e6, 0.5, 1e-3), (1e10, 1.0, 1e-3), (1.0, 1e-150, 1e-3), (3.0, -2.0, 0.2)],
)
def test_scalar_gradient_step_is_the_exact_exponential_solution(gamma, delta, dt):
    theta, Y = 0.3, -1.2
    target = Y / delta
    exact = target + (theta - target) * np.exp(-gamma * delta * delta * dt)
    new = scalar_gradient_step(np.array([theta]), np.array([Y]), delta, gamma, dt)[0]
    if abs(gamma * delta * delta * dt) < 1e-200:           # tiny Delta: compare the increment
        assert new - theta == pytest.approx(gamma * delta * (Y - delta * theta) * dt, rel=1e-12)
    else:
        assert new == pytest.approx(exact, rel=1e-12, abs=1e-14)


def test_discrete_step_and_finite_time_estimate_follow_their_identities():
    theta_true = np.array([1.0, -2.0])
    delta, k = 0.4, 0.01
    new = discrete_scalar_gradient_step(np.zeros(2), delta * theta_true, delta, k)
    np.testing.assert_allclose(theta_true - new, theta_true / (1.0 + delta**2 / k), rtol=1e-14)
    theta0 = np.array([5.0, 5.0])
    for nu in (0.3, 1e-6, 0.0):                             # any nu < mu: exact
        theta_hat = theta_true - nu * (theta_true - theta0)
        np.testing.assert_allclose(finite_time_estimate(theta_hat, theta0, nu, 0.5), theta_true, rtol=1e-14)
