"""The noise check (issue 38): ``fluctuation`` measures what noise leaves in an error and a smooth decay does not,
and a sweep's summary warns when it exceeds the tolerance."""

import numpy as np
import pytest

from obsfmu.fmus.campaign.measures import Measure
from obsfmu.fmus.campaign.table import _noise_lines
from obsfmu.fmus.metrics import fluctuation

TIME = np.linspace(0.0, 10.0, 10001)


@pytest.mark.parametrize("sigma", [1e-3, 1e-2, 1.0])
def test_fluctuation_is_the_standard_deviation_of_white_noise_on_a_decay(sigma):
    noise = np.random.default_rng(1).normal(0.0, sigma, TIME.size)
    # 1001 samples in the last 10 %: the estimate of sigma within 3 standard errors (2.2 %) plus the fit's 3 dof
    assert fluctuation(TIME, 5.0 * np.exp(-TIME / 2.0) + noise) == pytest.approx(sigma, rel=0.07)


def test_a_smooth_decay_or_drift_has_no_fluctuation():
    # the last 10 % is half a time constant: a quadratic leaves 3.1e-4 of the decay's size there (measured)
    assert fluctuation(TIME, np.exp(-TIME / 2.0)) < 1e-3 * np.exp(-9.0 / 2.0)
    assert fluctuation(TIME, 0.3 + 0.01 * TIME) < 1e-12
    assert np.isnan(fluctuation(TIME[:20], np.zeros(20)))                        # fewer than 5 points in the window


def test_the_sweep_warns_when_three_standard_deviations_exceed_the_tolerance():
    measure = Measure(("convergence_time a",), ("final_error a",), "a below 0.01", "final |a|",
                      noise=(("fluctuation a", 0.01),))
    quiet = {"status": "ok", "fluctuation a": 1e-3}                  # 3 sigma = 0.3 tolerance
    loud = {"status": "ok", "fluctuation a": 1e-2}                   # 3 sigma = 3 tolerances
    assert _noise_lines(measure, [quiet, quiet]) == []
    assert _noise_lines(measure, [{"status": "ok"}]) == []           # rows stored before the metric: no verdict
    (line,) = _noise_lines(measure, [quiet, loud, {**loud, "status": "error"}])
    assert "in 1 of 3 sample(s)" in line and "up to 3 times its tolerance" in line
    assert "the tolerance is below the noise-induced error" in line
