"""``LeastSquaresForgetting.error_bound``: a guaranteed bound on |theta_hat - theta|_2 (issue 27, item 2)."""

import math

import numpy as np
from obsfmu.observers.estimation import LeastSquaresForgetting

THETA = np.array([1.0, 2.0, -1.0])
DT = 1e-3


def trace(noise=0.0, M=1e12, seconds=8.0, seed=0, third=1.0):
    """(error, bound, lambda_min, decay) at every step of phi = [sin t, cos t, third], |noise| <= ``noise``."""
    rng = np.random.default_rng(seed)
    est = LeastSquaresForgetting(3, 1000.0, 1.0, 0.1, M)
    initial = np.linalg.norm(THETA)                 # theta_hat(0) = 0
    rows = []
    for k in range(int(seconds / DT)):
        t = k * DT
        phi = np.array([math.sin(t), math.cos(t), third])
        est.update(phi @ THETA + noise * rng.uniform(-1.0, 1.0), phi, DT)
        rows.append((np.linalg.norm(est.theta_hat - THETA), est.error_bound(initial, noise), est.lambda_min,
                     est.decay))
    return np.array(rows), est


def test_the_bound_holds_and_is_tight_for_an_exact_regression():
    rows, _ = trace()
    error, bound = rows[:, 0], rows[:, 1]
    assert np.all(error <= bound * (1 + 1e-9) + 1e-13)
    assert bound[-1] < 1e-5 and error[-1] > 0.01 * bound[-1]        # measured ratio ~0.1-0.6


def test_the_bound_holds_with_a_bounded_regression_error():
    rows, _ = trace(noise=1e-2, seconds=4.0)
    assert np.all(rows[:, 0] <= rows[:, 1])
    assert rows[-1, 1] < 0.05


def test_after_the_gain_freezes_the_bound_still_holds():
    """``phi_3 = 0``: ``F_33 = 10 e^t`` reaches ``M = 20`` after ln 2 s; the excited entries still converge."""
    rows, est = trace(M=20.0, seconds=6.0, third=0.0)
    assert est.frozen
    assert np.all(rows[:, 0] <= rows[:, 1] * (1 + 1e-9) + 1e-13)
    assert est.error_bound(1.0, 1e-3) == math.inf                  # no bound with noise once frozen


def test_an_optimistic_bound_fails_the_same_check():
    """Mutation: dropping the 1 / lambda_min(P) factor gives a 'bound' the error exceeds."""
    rows, _ = trace(seconds=3.0)
    optimistic = 0.1 * rows[:, 3] * np.linalg.norm(THETA)
    assert np.any(rows[:, 0] > optimistic)


def test_without_noise_the_bound_never_increases():
    """``lambda_min(P) e^{beta t}`` never decreases, so ``converged`` stays true once true."""
    rows, _ = trace(seconds=2.0)
    assert np.all(np.diff(rows[:, 1]) <= 1e-12 * rows[:-1, 1])
