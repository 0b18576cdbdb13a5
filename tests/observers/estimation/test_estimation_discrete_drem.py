"""DiscreteDREM (paper 000, Statement 2) against its analytic error recursion."""

import numpy as np
import pytest

from obsfmu.observers.checks import ParameterError, SignalError
from obsfmu.observers.estimation import DelayExtension, DiscreteDREM


def run(estimator, theta, regressors):
    return np.array([estimator.update(phi @ theta, phi) for phi in regressors])


@pytest.mark.parametrize("normalize", [True, False])
def test_error_follows_the_statement_2_recursion_exactly(normalize):
    # phi(k) = [sin k, cos k], one-sample delay: Delta = sin k cos(k-1) - cos k sin(k-1) = sin 1
    # (unit rows, so normalising changes nothing) and theta_tilde(k) = theta_tilde(0) (1 + sin(1)^2/k)^-k.
    theta, gain = np.array([1.0, 2.0]), 0.5
    regressors = [np.array([np.sin(k), np.cos(k)]) for k in range(21)]
    estimates = run(DiscreteDREM(DelayExtension([1]), gain, normalize=normalize), theta, regressors)
    np.testing.assert_array_equal(estimates[0], 0.0)       # sample 0: no delayed row yet, Delta = 0
    for k in range(1, 21):
        expected = theta * (1.0 + np.sin(1.0) ** 2 / gain) ** (-k)
        np.testing.assert_allclose(theta - estimates[k], expected, rtol=1e-9, atol=1e-14)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_p10_random_bounded_regressors_reach_1e_8(seed):
    rng = np.random.default_rng(seed)
    p = 10
    theta = rng.uniform(-2.0, 2.0, p)
    regressors = rng.uniform(-1.0, 1.0, size=(60, p))
    estimates = run(DiscreteDREM(DelayExtension(range(1, p)), 1e-4), theta, regressors)
    errors = np.max(np.abs(estimates - theta), axis=1)
    assert errors[-1] < 1e-8
    assert np.argmax(errors < 1e-8) <= 40                  # measured: samples 35, 19, 31


def test_p10_normalised_estimates_do_not_depend_on_the_signal_scale():
    rng = np.random.default_rng(4)
    p = 10
    theta = rng.uniform(-2.0, 2.0, p)
    regressors = rng.uniform(-1.0, 1.0, size=(40, p))
    reference = run(DiscreteDREM(DelayExtension(range(1, p)), 1e-4), theta, regressors)
    for scale in (1e-40, 1e-3, 1e3, 1e40):
        scaled = run(DiscreteDREM(DelayExtension(range(1, p)), 1e-4), theta, scale * regressors)
        np.testing.assert_allclose(scaled, reference, rtol=1e-9, atol=1e-12)
    # without normalisation: rows of size 1e-3 give Delta ~ 1e-30, the law does not move
    raw = run(DiscreteDREM(DelayExtension(range(1, p)), 1e-4, normalize=False), theta, 1e-3 * regressors)
    assert np.max(np.abs(raw[-1] - theta)) > 0.1
    with pytest.raises(SignalError, match="Delta"):
        run(DiscreteDREM(DelayExtension(range(1, p)), 1e-4, normalize=False), theta, 1e40 * regressors)


def test_vector_regression_with_two_rows_and_two_delays():
    rng = np.random.default_rng(9)
    theta = rng.uniform(-1.0, 1.0, 6)
    est = DiscreteDREM(DelayExtension([1, 2], rows=2), 1e-3)
    for k in range(60):
        Phi = rng.uniform(-1.0, 1.0, size=(2, 6))
        est.update(Phi @ theta, Phi)
    assert est.samples == 60
    assert np.max(np.abs(est.theta_hat - theta)) < 1e-8


def test_dt_must_be_one_sample():
    est = DiscreteDREM(DelayExtension([1]), 0.1)
    phi = np.array([1.0, 0.5])
    est.update(1.0, phi, 1)
    est.update(1.0, phi)
    with pytest.raises(ParameterError, match="dt"):
        est.update(1.0, phi, 1e-3)


def test_the_round_off_floor_keeps_a_weak_corrupted_sample_from_moving_an_exact_estimate():
    """relative_floor: k' = max(k, floor Delta_max^2).  After a strong sample (Delta = sin 1) a sample whose
    Delta is 1e-7 and whose Y carries an error of 1e-16 (round-off) moves the paper's law (k = 1e-30) by
    1e-16 / 1e-7 = 1e-9; with a floor of 1e-8 by (1e-14 / 1e-8) 1e-16 / 1e-7 ~ 1e-15.  The error identity holds
    with k' (contraction)."""
    theta = np.array([1.0, 2.0])
    strong = [np.array([np.sin(k), np.cos(k)]) for k in range(3)]
    for floor, (low, high) in ((0.0, (5e-10, 2e-9)), (1e-8, (0.0, 1e-14))):       # measured 1.05e-9, 1.6e-15
        est = DiscreteDREM(DelayExtension([1]), 1e-30, normalize=False, relative_floor=floor)
        run(est, theta, strong)
        assert np.max(np.abs(est.theta_hat - theta)) < 1e-14
        # a weak pair: rows (1, 0) and (1, 1e-7) -> Delta = 1e-7; Y off by 1e-16 at the second
        est.update(np.array([1.0, 0.0]) @ theta, np.array([1.0, 0.0]))
        before = est.theta_hat.copy()
        est.update(np.array([1.0, 1e-7]) @ theta + 1e-16, np.array([1.0, 1e-7]))
        moved = np.max(np.abs(est.theta_hat - before))
        assert low <= moved < high, (floor, moved)
    # exact data: theta_tilde(k) = contraction * theta_tilde(k-1), contraction = k' / (k' + Delta^2)
    est = DiscreteDREM(DelayExtension([1]), 1e-3, normalize=False, relative_floor=0.5, theta0=[0.0, 0.0])
    errors = [theta.copy()]
    for phi in [np.array([np.sin(k), np.cos(k)]) for k in range(8)]:
        est.update(phi @ theta, phi)
        np.testing.assert_allclose(theta - est.theta_hat, est.contraction * errors[-1], rtol=1e-9, atol=1e-15)
        errors.append(theta - est.theta_hat)
    assert est.delta_max == pytest.approx(np.sin(1.0)) and np.all(est.contraction > 0.3)   # k' = 0.5 sin^2 1


def test_the_round_off_floor_is_a_number_in_0_1():
    for floor in (-1e-3, 1.0, float("nan")):
        with pytest.raises(ParameterError, match="relative_floor"):
            DiscreteDREM(DelayExtension([1]), 1e-8, relative_floor=floor)
