"""The diagnostics contract on every paper scenario (issue 27, item 2; docs/estimation.md, "Diagnostics").

Every adaptive observer FMU has the outputs ``excitation`` (>= 0) and ``converged`` (0/1).  On each
paper scenario: ``converged`` becomes true (at the time stated in docs/estimation.md), and at
every time it is true -- in particular the first -- the true parameter error is within the
observer's ``converged_tolerance``.  Mutation checks: a deliberately optimistic criterion (an
assumption broken through the parameters, or a looser test on the recorded diagnostics) makes
the same check find false claims, so the check can fail.
"""

import numpy as np
import pytest

from obsfmu.fmus.metrics import time_to_stay_below
from obsfmu.fmus.scenarios import run
from obsfmu.fmus.scenarios.discrete_gpebo import true_gammas
from obsfmu.fmus.scenarios.uio_ftdrem import X0, true_x_tilde0


def _vector(result, name):
    try:
        return result.vector(name)
    except (KeyError, ValueError):
        return result[name][:, None]


def _difference(result, pairs):
    return np.max(np.column_stack([np.abs(_vector(result, a) - _vector(result, b)) for a, b in pairs]), axis=1)


def ltv_error(result):
    return _difference(result, [("observer.theta_hat", "plant.theta")])


def state_affine_error(result):
    return _difference(result, [("observer.theta_hat", "plant.theta")])


def uio_error(result):
    """xi(0) (plant ``xi``, constant: Gamma = 0), the frequency, and x_tilde(0) of stage 1."""
    x_tilde0 = np.abs(result.vector("observer.x_tilde0_hat") - true_x_tilde0(X0)).max(axis=1)
    return np.maximum(_difference(result, [("observer.xi0_hat", "plant.xi"),
                                           ("observer.omega_hat", "plant.f_omega")]), x_tilde0)


def gpebo_error(result):
    """gamma, and eta through beta(k), theta(k) (the example's generators have |Gamma^k| = 1)."""
    gamma = np.abs(result.vector("observer.gamma_hat") - true_gammas(result)).max(axis=1)
    return np.maximum(gamma, _difference(result, [("observer.beta_hat", "plant.beta"),
                                                  ("observer.theta_hat", "plant.theta")]))


#: scenario -> (error, tolerance the scenario configures, time converged first becomes true (measured))
CASES = {
    "ltv-ls": (ltv_error, 1e-3, 14.075),
    "ltv-ls-bounded": (ltv_error, 1e-2, 18.28),
    "state-affine-pendulum": (state_affine_error, 1e-3, 2.848),
    "state-affine-chemostat": (state_affine_error, 1e-3, 3.984),
    "uio-ftdrem": (uio_error, 1e-3, 7.559),
    "discrete-gpebo": (gpebo_error, 1e-6, 18.0),
}


def false_claims(time, error, converged, tolerance):
    """Times at which ``converged`` is true while the true error exceeds ``tolerance``."""
    return time[(converged > 0.5) & (error > tolerance)]


def flag_times(result, error, tolerance):
    """(first time converged is true, time the error stays below the tolerance)."""
    converged = result["observer.converged"]
    first = result.time[np.argmax(converged > 0.5)] if converged.any() else np.inf
    return first, time_to_stay_below(result.time, error, tolerance)


@pytest.fixture(scope="module")
def runs(build_dir):
    return {}


def scenario_run(runs, build_dir, name):
    if name not in runs:
        runs[name], _ = run(name, build_dir)
    return runs[name]


@pytest.mark.parametrize("name", sorted(CASES))
def test_converged_is_never_a_false_claim_and_comes(runs, build_dir, name):
    error_of, tolerance, first_expected = CASES[name]
    result = scenario_run(runs, build_dir, name)
    assert result.info.defaults["observer.converged_tolerance"] == tolerance
    converged, excitation, error = result["observer.converged"], result["observer.excitation"], error_of(result)
    assert set(np.unique(converged)) <= {0.0, 1.0}
    assert np.all(excitation >= 0.0) and np.all(np.isfinite(excitation))
    assert false_claims(result.time, error, converged, tolerance).size == 0
    first, truly = flag_times(result, error, tolerance)
    assert first == pytest.approx(first_expected, abs=1e-6), (first, truly)
    assert first >= truly, "the flag may not come before the error stays below the tolerance here"
    assert converged[-1] == 1.0


@pytest.mark.parametrize("name, overrides, stop_time", [
    ("ltv-ls", {"theta_bound": 1e-9}, 3.0),                          # a false a-priori bound
    ("uio-ftdrem", {"settle_tol": 0.1, "decay_rate": 1e4}, 8.0),     # a loose test, a false decay rate
])
def test_an_optimistic_criterion_makes_the_check_fail(build_dir, name, overrides, stop_time):
    error_of, tolerance, _ = CASES[name]
    result, _ = run(name, build_dir, stop_time=stop_time,
                    overrides=[("observer", key, value) for key, value in overrides.items()])
    assert false_claims(result.time, error_of(result), result["observer.converged"], tolerance).size > 0


@pytest.mark.parametrize("name, optimistic", [
    ("state-affine-pendulum", lambda r: r["observer.nu"] < 0.999),       # ignores the switch nu < mu
    ("state-affine-chemostat", lambda r: r["observer.nu"] < 0.999),
    ("discrete-gpebo", lambda r: r["observer.nu_gamma"] < 1e-3),          # ignores theta_bound and eta
])
def test_an_optimistic_flag_from_the_recorded_diagnostics_fails_the_check(runs, build_dir, name, optimistic):
    error_of, tolerance, _ = CASES[name]
    result = scenario_run(runs, build_dir, name)
    flag = optimistic(result).astype(float)
    assert false_claims(result.time, error_of(result), flag, tolerance).size > 0
