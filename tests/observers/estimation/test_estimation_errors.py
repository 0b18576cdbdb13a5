"""Bad configuration and bad signals: clear errors that name the parameter, state untouched."""

import math

import numpy as np
import pytest

from obsfmu.observers.checks import ParameterError, SignalError
from obsfmu.observers.estimation import (
    DREM,
    DelayExtension,
    DiscreteDREM,
    FilterBankExtension,
    FiniteTimeDREM,
    Gradient,
    KreisselmeierExtension,
    LeastSquaresForgetting,
)

THETA = np.array([1.0, 2.0])

# each factory returns (estimator, its step)
ESTIMATORS = {
    "gradient": lambda: (Gradient(2, 1.0), 0.05),
    "least-squares": lambda: (LeastSquaresForgetting(2, 1000.0, 1.0, 0.1, 1e12), 0.05),
    "drem-filter-bank": lambda: (DREM(FilterBankExtension([1.0]), 10.0), 0.05),
    "drem-kreisselmeier": lambda: (DREM(KreisselmeierExtension(2, 1.0), 10.0), 0.05),
    "drem-delays": lambda: (DREM(DelayExtension([3]), 10.0), 0.05),
    "ft-drem": lambda: (FiniteTimeDREM(FilterBankExtension([1.0]), 10.0, 0.5), 0.05),
    "discrete-drem": lambda: (DiscreteDREM(DelayExtension([1]), 0.1), 1),
}


def feed(estimator, dt, samples):
    for k in samples:
        phi = np.array([np.sin(0.3 * k), np.cos(0.3 * k)])
        estimator.update(phi @ THETA, phi, dt)
    return estimator.theta_hat.copy()


BAD_SAMPLES = [
    (math.nan, [1.0, 0.0], SignalError, "y"),
    (1.0, [math.inf, 0.0], SignalError, "phi"),
    (1.0, [0.5, -math.inf], SignalError, "phi"),
    (math.nan, [math.nan, 1.0], SignalError, "y"),
    (1.0, [1.0, 2.0, 3.0], ParameterError, "phi"),          # p = 3 instead of 2
    ([1.0, 2.0], [1.0, 2.0], ParameterError, "y"),          # two outputs for one regressor row
    (1.0, [[[1.0, 2.0]]], ParameterError, "phi"),           # 3-D
    ("one", [1.0, 2.0], ParameterError, "y"),
]


@pytest.mark.parametrize("name", ESTIMATORS)
@pytest.mark.parametrize("y, phi, error, parameter", BAD_SAMPLES)
def test_bad_sample_is_refused_and_changes_nothing(name, y, phi, error, parameter):
    estimator, dt = ESTIMATORS[name]()
    twin, _ = ESTIMATORS[name]()
    before = feed(estimator, dt, range(10))
    feed(twin, dt, range(10))
    with pytest.raises(error, match=rf"^{parameter}\b"):
        estimator.update(y, phi, dt)
    np.testing.assert_array_equal(estimator.theta_hat, before)
    # the whole state (filters, delay lines, P, nu, ...) is untouched: the future is identical
    np.testing.assert_array_equal(feed(estimator, dt, range(10, 30)), feed(twin, dt, range(10, 30)))


@pytest.mark.parametrize("name", [n for n in ESTIMATORS if n != "discrete-drem"])
@pytest.mark.parametrize("dt", [0.0, -1e-3, math.nan, math.inf, "abc"])
def test_bad_step_is_refused(name, dt):
    estimator, _ = ESTIMATORS[name]()
    with pytest.raises(ParameterError, match=r"^dt\b"):
        estimator.update(1.0, [1.0, 0.0], dt)
    np.testing.assert_array_equal(estimator.theta_hat, 0.0)


def test_regression_rows_must_match_the_extension():
    estimator = DREM(FilterBankExtension([1.0]), 1.0)      # built for one row
    with pytest.raises(ParameterError, match=r"^phi\b.*1 row"):
        estimator.update([1.0, 2.0], [[1.0, 0.0], [0.0, 1.0]], 0.01)


BAD_CONFIGURATIONS = [
    (lambda: Gradient(0, 1.0), "p"),
    (lambda: Gradient(2.5, 1.0), "p"),
    (lambda: Gradient(2, 0.0), "gamma"),
    (lambda: Gradient(2, -1.0), "gamma"),
    (lambda: Gradient(2, math.nan), "gamma"),
    (lambda: Gradient(2, 1.0, theta0=[1.0, 2.0, 3.0]), "theta0"),
    (lambda: LeastSquaresForgetting(2, 0.0, 1.0, 0.1, 1e12), "gamma"),
    (lambda: LeastSquaresForgetting(2, 1.0, 0.0, 0.1, 1e12), "beta"),
    (lambda: LeastSquaresForgetting(2, 1.0, 1.0, 0.0, 1e12), "f0"),
    (lambda: LeastSquaresForgetting(2, 1.0, 1.0, 0.1, -1.0), "M"),
    (lambda: DREM(FilterBankExtension([1.0]), 0.0), "gamma"),
    (lambda: DREM(FilterBankExtension([1.0]), [1.0, 2.0, 3.0]), "gamma"),
    (lambda: DREM(FilterBankExtension([1.0]), [1.0, -2.0]), "gamma"),
    (lambda: DREM("filters", 1.0), "extension"),
    (lambda: DREM(FilterBankExtension([1.0]), 1.0, theta0=[0.0]), "theta0"),
    (lambda: FilterBankExtension([0.0]), "rates"),
    (lambda: FilterBankExtension([1.0, 1.0]), "rates"),
    (lambda: FilterBankExtension([1.0], rows=0), "rows"),
    (lambda: DelayExtension([1.5]), "delays"),
    (lambda: DelayExtension([0]), "delays"),
    (lambda: DelayExtension([2, 2]), "delays"),
    (lambda: KreisselmeierExtension(2, -1.0), "a"),
    (lambda: FiniteTimeDREM(FilterBankExtension([1.0]), 1.0, mu=1.0), "mu"),
    (lambda: FiniteTimeDREM(FilterBankExtension([1.0]), 1.0, mu=0.0), "mu"),
    (lambda: DiscreteDREM(DelayExtension([1]), 0.0), "k"),
    (lambda: DiscreteDREM(FilterBankExtension([1.0]), 1.0), "extension"),
]


@pytest.mark.parametrize("build, parameter", BAD_CONFIGURATIONS)
def test_bad_configuration_names_the_parameter(build, parameter):
    with pytest.raises(ParameterError, match=rf"^{parameter}:"):
        build()
