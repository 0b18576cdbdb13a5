"""The determinant regression with whole unknown gamma vectors (CompanionRegression) and the observer on it."""

import numpy as np
import pytest

from obsfmu.observers.block import Segment
from obsfmu.observers.checks import ParameterError
from obsfmu.observers.gpebo import GeneratorModel, GpeboObserver
from obsfmu.observers.gpebo.companion import CompanionRegression
from obsfmu.observers.gpebo.regression import ShiftRegression, regression_for
from obsfmu.plants.gpebo import GeneratorPlant

TANH2 = lambda y: np.array([np.tanh(y), 0.0])      # noqa: E731  (f of the n = 2 structures)
EXAMPLE_STRUCTURE = dict(n=2, h_beta=[1.0, 0.0], H_theta=[[1.0, 0.0], [0.0, 0.0]], H_delta=None, f=TANH2)
DAMPED, UNDAMPED = [1.0, -0.96], [1.2, -1.0]


def model_of(n, h_beta, H_theta, H_delta, f):
    return GeneratorModel.checked(n, h_beta, H_theta, H_delta, f)


def record(model, vectors, samples=80):
    """u, y, x of the plant with generator vectors ``vectors`` driven by sin k + 0.5 sin 2.3 k."""
    l, m, r = model.sizes
    xi0 = [np.linspace(1.0, 0.3, l), np.linspace(0.5, -0.4, m), np.linspace(0.2, 0.1, r)]
    delta = (vectors[2], xi0[2]) if r else ()
    plant = GeneratorPlant(model, vectors[0], vectors[1], xi0[0], xi0[1], np.linspace(0.3, -0.2, model.n), 1.0,
                           *delta)
    u = np.sin(np.arange(samples)) + 0.5 * np.sin(2.3 * np.arange(samples))
    y, x = [], []
    for k in range(samples):
        y.append(plant.x[0])
        x.append(plant.x.copy())
        plant.advance(k, 1.0, {"u": Segment.hold([u[k]])})
    return u, np.array(y), np.array(x)


def rows(regression, u, y) -> tuple[np.ndarray, np.ndarray]:
    w = regression.window
    pairs = [regression.row(u[k - w + 1:k + 1], y[k - w + 1:k + 1]) for k in range(w - 1, len(y))]
    return np.array([z for z, _ in pairs]), np.array([r for _, r in pairs])


def residual(regression, u, y, truth) -> float:
    """Largest |zeta - rho^T sigma(gamma)| / |(zeta, rho)| over the record."""
    zeta, rho = rows(regression, u, y)
    return float(np.max(np.abs(zeta - rho @ regression.sigma(*truth)) / np.hypot(zeta, np.linalg.norm(rho, axis=1))))


def generic_rank(regression, seed=0) -> int:
    rng = np.random.default_rng(seed)
    samples = regression.window + 3 * regression.p
    _, rho = rows(regression, rng.standard_normal(samples), rng.uniform(0.2, 1.2, samples))
    singular = np.linalg.svd(rho / np.linalg.norm(rho, axis=1)[:, None], compute_uv=False)
    return int(np.sum(singular > 1e-9 * singular[0]))


CASES = [   # structure, unknown forms, generator vectors, p
    (EXAMPLE_STRUCTURE, ("all", "all"), (UNDAMPED, DAMPED), 29),
    (EXAMPLE_STRUCTURE, ("all", "last"), (UNDAMPED, [0.0, 1.0]), 17),
    (EXAMPLE_STRUCTURE, ("last", "all"), ([0.0, -1.0], DAMPED), 17),
    (dict(n=2, h_beta=[1.0], H_theta=np.zeros((2, 0)), H_delta=[[0.0, 0.0], [1.0, 0.0]], f=TANH2),
     ("last", "last", "all"), ([0.9], [], DAMPED), None),      # beta(k+1) = 0.9 beta(k), delta2 damped
]


@pytest.mark.parametrize("structure, unknown, vectors, p", CASES)
def test_the_regression_holds_on_exact_data_and_has_full_rank(structure, unknown, vectors, p):
    model = model_of(**structure)
    regression = regression_for(model, unknown)
    assert isinstance(regression, CompanionRegression)
    if p is not None:
        assert regression.p == p
    truth = regression.unknowns(*[np.asarray(v) for v in vectors])
    u, y, _ = record(model, vectors)
    assert residual(regression, u, y, truth) < 1e-13
    wrong = truth + 0.01
    assert residual(regression, u, y, wrong) > 1e-6                # a wrong gamma violates it
    assert generic_rank(regression) == regression.p
    np.testing.assert_allclose(regression.gammas(regression.sigma(*truth)), truth, rtol=1e-14)
    for vector, full in zip(vectors, regression.full_coefficients(truth)):
        np.testing.assert_array_equal(full, vector)


def test_unknown_names_order_and_divisors():
    regression = CompanionRegression(model_of(**EXAMPLE_STRUCTURE), ("all", "all"))
    assert regression.names == ("gamma_beta[1]", "gamma_beta[2]", "gamma_theta[1]", "gamma_theta[2]")
    assert [regression.names[v] for v in regression.divisors] == ["gamma_beta[2]", "gamma_theta[2]"]
    with pytest.raises(ParameterError, match=r"gamma_theta\[2\]: must be nonzero"):
        regression.sigma(1.2, -1.0, 1.0, 0.0)
    assert regression.window == 2 + 5                   # n + R, R = 1 + 2 + 2


def test_error_bound_covers_the_recovery():
    regression = CompanionRegression(model_of(**EXAMPLE_STRUCTURE), ("all", "all"))
    truth = np.array(UNDAMPED + DAMPED)
    sigma, rng = regression.sigma(*truth), np.random.default_rng(1)
    assert regression.error_bound(sigma, np.zeros(regression.p)) == 0.0
    for scale in (1e-9, 1e-6, 1e-3):
        error = scale * np.abs(sigma)
        for _ in range(20):
            moved = sigma + error * rng.uniform(-1, 1, sigma.size)
            assert np.max(np.abs(regression.gammas(moved) - truth)) <= regression.error_bound(moved, error)


def test_every_last_keeps_the_existing_regressions():
    model = model_of(**EXAMPLE_STRUCTURE)
    assert not isinstance(regression_for(model, ("last", "last", "last")), CompanionRegression)
    shift3 = model_of(3, [1.0, 0.0, 0.0], np.eye(3)[:, [1]] @ np.eye(3)[[0]], None,
                      lambda y: np.array([0.0, np.tanh(y), 0.0]))
    assert isinstance(regression_for(shift3, None), ShiftRegression)


@pytest.mark.parametrize("structure, unknown, match", [
    (dict(n=3, h_beta=[1.0, 0.0, 0.0], H_theta=np.eye(3)[:, [1, 0, 2]] * [[0], [1], [0]], H_delta=None,
          f=lambda y: np.array([0.0, np.tanh(y), 0.0])), ("all", "all"),
     r"gamma_beta_unknown: the full-gamma regression has 139 unknowns; at most 50"),
    (dict(n=2, h_beta=[1.0, 0.0, 0.0], H_theta=[[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]], H_delta=[[0.0, 0.0], [1.0, 0.0]],
          f=TANH2), ("last", "all", "last"),
     r"gamma_theta_unknown: with a whole gamma unknown the regression's matrix has R = 1 \+ sum of the term sizes "
     r"\[3, 3, 2\] = 9 rows; at most 7"),
    (EXAMPLE_STRUCTURE, ("all", "some"), r"gamma_unknown: expected at most 3 of \('last', 'all'\)"),
])
def test_limits_are_refused_naming_the_field(structure, unknown, match):
    with pytest.raises(ParameterError, match=match):
        CompanionRegression(model_of(**structure), unknown)


def run_observer(model, vectors, unknown, k_gamma, samples=80):
    u, y, x = record(model, vectors, samples)
    observer = GpeboObserver(model, 1.0, k_gamma=k_gamma, gamma_hat0=[0.5] * 4, gamma_unknown=unknown)
    truth = observer.regression.unknowns(*[np.asarray(v) for v in vectors])
    gamma_errors, x_errors, flags = [], [], []
    for k in range(samples):
        out = observer.outputs(k, {})
        gamma_errors.append(np.max(np.abs(out["gamma_hat"] - truth)))
        x_errors.append(np.max(np.abs(out["x_hat"] - x[k])))
        flags.append(out["converged"][0])
        observer.advance(k, 1.0, {"u": Segment.hold([u[k]]), "y": Segment.hold([y[k]])})
    return observer, np.array(gamma_errors), np.array(x_errors), np.array(flags)


def test_observer_with_whole_gammas_converges_and_certifies_late_never_early():
    model = model_of(**EXAMPLE_STRUCTURE)
    observer, gamma_errors, x_errors, flags = run_observer(model, (UNDAMPED, DAMPED), ("all", "all"), 1e-30)
    assert observer.excited and gamma_errors[-1] < 1e-12 and x_errors[-1] < 1e-11
    assert flags.any() and np.all(gamma_errors[flags > 0] <= 1e-6) and np.all(x_errors[flags > 0] <= 1e-6)


def test_the_default_gain_is_too_large_for_29_unknowns():
    """|Delta| of 29 normalised rows stays below ~1e-13: k_gamma = 1e-8 leaves nu_gamma at 1 (not excited)."""
    model = model_of(**EXAMPLE_STRUCTURE)
    observer, gamma_errors, _, flags = run_observer(model, (UNDAMPED, DAMPED), ("all", "all"), 1e-8)
    assert not observer.excited and observer.nu_gamma > 0.999 and gamma_errors[-1] > 0.1 and not flags.any()
