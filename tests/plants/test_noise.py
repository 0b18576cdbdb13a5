"""plants/noise.py: reproducible by seed whatever the order and step of evaluation, sample statistics
within stated bounds, band-limited variance and correlation against the filter's analytic values
(scipy, independently of the code's own discretisation), noise on a connection, bad parameters named."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import expm, solve_discrete_lyapunov

from obsfmu.observers.checks import ParameterError
from obsfmu.observers.state import capture
from obsfmu.observers.integrators import BudgetError
from obsfmu.plants.noise import CHECKPOINT, AddedNoise, Noise, NoiseSource
from obsfmu.plants.signals import SampledNoise

#: number of sample intervals x streams of the statistical tests
INTERVALS, STREAMS = 4000, 25


def _samples(noise: Noise, count: int = INTERVALS) -> np.ndarray:
    return np.array([noise.sample(k) for k in range(count)])


# --- reproducibility ------------------------------------------------------------------------------------

@pytest.mark.parametrize("options", [{}, {"distribution": "uniform"}, {"cutoff_hz": 3.0},
                                     {"cutoff_hz": 3.0, "filter_order": 2, "distribution": "uniform"}])
def test_same_seed_same_stream_whatever_the_step_and_the_order(options):
    dt, stop = 0.01, 2.5 * CHECKPOINT * 0.01     # past two checkpoints of the filter
    reference = Noise(0.7, dt, 42, size=3, **options)
    by_interval = {k: reference.sample(k) for k in range(int(stop / dt) + 1)}
    for step in (dt / 7, dt, 3.3 * dt):
        noise = Noise(0.7, dt, 42, size=3, **options)
        for t in np.arange(0.0, stop, step):
            k = int(math.floor(t / dt + 1e-9))
            assert noise(t).tolist() == by_interval[k].tolist()
    shuffled = Noise(0.7, dt, 42, size=3, **options)
    order = np.random.default_rng(1).permutation(len(by_interval))
    for k in order:                              # jumps back and forth across checkpoints
        assert shuffled(k * dt + dt / 2).tolist() == by_interval[k].tolist()
    assert Noise(0.7, dt, 42, size=3, **options)(-1.0).tolist() == by_interval[0].tolist()


def test_gaussian_white_noise_is_the_one_of_sampled_noise():
    noise, old = Noise(0.3, 0.02, 11, size=2), SampledNoise(0.3, 0.02, 11, size=2)
    for t in np.linspace(0.0, 3.0, 301):
        assert noise(t).tolist() == old(t).tolist()


@pytest.mark.parametrize("options", [{}, {"distribution": "uniform"}, {"cutoff_hz": 3.0, "filter_order": 2}])
def test_seeds_and_streams_differ(options):
    a, b = _samples(Noise(1.0, 0.01, 1, size=2, **options), 500), _samples(Noise(1.0, 0.01, 2, size=2, **options), 500)
    assert np.all(a != b)
    # |correlation| of independent streams over ~500 samples (~50 for the filtered ones): < 4.5 / sqrt(N)
    effective = 500 if not options.get("cutoff_hz") else 50
    for x, y in ((a[:, 0], b[:, 0]), (a[:, 0], a[:, 1])):
        assert abs(np.corrcoef(x, y)[0, 1]) < 4.5 / math.sqrt(effective)


# --- statistics of the white sequence -------------------------------------------------------------------

@pytest.mark.parametrize("distribution, fourth_moment", [("gaussian", 3.0), ("uniform", 9.0 / 5.0)])
def test_white_noise_mean_and_std_within_bounds(distribution, fourth_moment):
    """N = 100 000 independent samples: mean within 5 sigma / sqrt(N); variance within
    5 sqrt((m4 - sigma^4) / N) (m4 the fourth moment: 3 sigma^4 Gaussian, 9/5 sigma^4 uniform)."""
    std = 0.4
    w = _samples(Noise(std, 0.001, 7, size=STREAMS, distribution=distribution)).ravel()
    N = w.size
    assert abs(w.mean()) < 5 * std / math.sqrt(N)
    assert abs(w.var() - std ** 2) < 5 * std ** 2 * math.sqrt((fourth_moment - 1.0) / N)
    if distribution == "uniform":
        assert np.max(np.abs(w)) <= math.sqrt(3.0) * std and np.max(np.abs(w)) > 0.99 * math.sqrt(3.0) * std
    else:
        tail, p = np.mean(np.abs(w) > 3 * std), 0.0026998              # P(|N(0, 1)| > 3)
        assert abs(tail - p) < 5 * math.sqrt(p * (1 - p) / N)


def test_zero_std_is_silent():
    assert _samples(Noise(0.0, 0.1, 3, size=2, cutoff_hz=1.0), 10).tolist() == [[0.0, 0.0]] * 10


# --- band-limited noise ---------------------------------------------------------------------------------

def _analytic(cutoff_hz: float, order: int, dt: float, std: float) -> tuple[float, np.ndarray, np.ndarray]:
    """Stationary variance of z_k and the exact discretisation (scipy), written without the code under test."""
    wc = 2 * math.pi * cutoff_hz
    if order == 1:
        a = math.exp(-wc * dt)
        return std ** 2 * (1 - a) / (1 + a), np.array([[a]]), np.array([[1 - a]])
    A = np.array([[0.0, 1.0], [-wc ** 2, -math.sqrt(2) * wc]])
    B = np.array([[0.0], [wc ** 2]])
    Ad = expm(A * dt)
    Bd = np.linalg.solve(A, (Ad - np.eye(2)) @ B)
    return float(solve_discrete_lyapunov(Ad, std ** 2 * Bd @ Bd.T)[0, 0]), Ad, Bd


@pytest.mark.parametrize("order", [1, 2])
def test_band_limited_variance_against_the_filter(order):
    """The variance of z_k over 4000 intervals x 25 streams is P[0, 0] within 8 %: the samples are
    correlated over ~1 / (wc dt) ~ 8 intervals, so the estimate has a relative standard deviation of
    1.4 % (first order) and 2.1 % (second order), measured over 12 seeds: 8 % is ~4 sigma.  The exact
    value (``variance()`` against scipy) is checked to rounding here, the recurrence in the next test."""
    std, dt, cutoff = 1.3, 0.01, 2.0
    noise = Noise(std, dt, 5, size=STREAMS, cutoff_hz=cutoff, filter_order=order)
    variance, Ad, _ = _analytic(cutoff, order, dt, std)
    assert noise.variance() == pytest.approx(variance, rel=1e-10)
    z = _samples(noise)
    assert z.var() == pytest.approx(variance, rel=0.08)
    assert abs(z.mean()) < 5 * math.sqrt(variance / (INTERVALS * STREAMS / 8))
    assert z[0].var() == pytest.approx(variance, rel=0.6)           # stationary from the first interval
    if order == 1:                                                  # lag-one correlation = the pole a
        lag = np.mean(z[1:] * z[:-1]) / np.mean(z * z)
        assert lag == pytest.approx(Ad[0, 0], abs=0.01)
    assert variance < 0.3 * std ** 2                                # it is band-limited indeed


@pytest.mark.parametrize("order", [1, 2])
def test_band_limited_recurrence_is_the_exact_discretisation(order):
    """z_{k+1} follows x_{k+1} = Ad x_k + Bd w_k with the held white samples of the same seed."""
    dt, cutoff = 0.005, 4.0
    noise = Noise(1.0, dt, 9, size=2, cutoff_hz=cutoff, filter_order=order)
    white = Noise(1.0, dt, 9, size=2)
    _, Ad, Bd = _analytic(cutoff, order, dt, 1.0)
    x = noise.filtered_state(0)
    for k in range(300):
        x = Ad @ x + Bd * white.sample(k)
        np.testing.assert_allclose(noise.sample(k + 1), x[0], rtol=1e-9, atol=1e-12)


def test_an_evaluation_beyond_the_interval_budget_is_refused_before_any_work():
    noise = Noise(1.0, 0.01, 3, cutoff_hz=1.0, interval_budget=500)
    first = noise(4.0)                                              # 400 filter steps: within
    with pytest.raises(BudgetError, match=r"^interval_budget: interval 901 needs 501 filter steps from interval 400"):
        noise(9.01)
    with pytest.raises(BudgetError, match=r"^interval_budget: "):
        noise(1e300)                                                # capped index, no overflow, no hang
    assert noise(4.0).tolist() == first.tolist()
    assert noise(9.0).tolist() == Noise(1.0, 0.01, 3, cutoff_hz=1.0)(9.0).tolist()
    assert Noise(1.0, 0.01, 3)(math.nan).tolist() == Noise(1.0, 0.01, 3)(0.0).tolist()


# --- blocks ---------------------------------------------------------------------------------------------

def test_noise_source_and_added_noise_blocks():
    source = NoiseSource(Noise(0.5, 0.1, 3, size=2, cutoff_hz=1.0))
    assert source.input_sizes == {} and source.output_sizes == {"y": 2} and source.stateless
    assert not source.feedthrough and source.derivative(0.3).tolist() == [0.0, 0.0]
    added = AddedNoise(Noise(0.5, 0.1, 3, size=2, cutoff_hz=1.0))
    assert added.input_sizes == {"u": 2} and added.output_sizes == {"y": 2} and added.feedthrough and added.stateless
    u = np.array([1.0, -2.0])
    for t in np.linspace(0.0, 30.0, 77):
        noise = source.outputs(t, {})["y"]
        assert np.array_equal(added.outputs(t, {"u": u})["y"], u + noise)
        added.advance(t, 0.1, {})
    assert capture(source) == {} and capture(added) == {}            # the filter cache is not state


@pytest.mark.parametrize("kwargs, message", [
    ({"std": -1.0}, r"^std: must be >= 0"),
    ({"sample_interval": 0.0}, r"^sample_interval: must be > 0"),
    ({"seed": -1}, r"^seed: expected an integer >= 0, got -1"),
    ({"seed": 1.5}, r"^seed: expected an integer >= 0, got 1.5"),
    ({"size": 0}, r"^size: expected an integer >= 1, got 0"),
    ({"distribution": "laplace"}, r"^distribution: expected 'gaussian' or 'uniform', got 'laplace'"),
    ({"cutoff_hz": 0.0}, r"^cutoff_hz: must be > 0"),
    ({"cutoff_hz": 1.0, "filter_order": 3}, r"^filter_order: expected 1 or 2, got 3"),
    ({"interval_budget": 0}, r"^interval_budget: expected an integer >= 1, got 0"),
])
def test_bad_parameter_is_named(kwargs, message):
    arguments = {"std": 1.0, "sample_interval": 0.1, "seed": 1} | kwargs
    with pytest.raises(ParameterError, match=message):
        Noise(**arguments)
