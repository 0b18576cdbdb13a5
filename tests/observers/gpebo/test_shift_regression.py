"""The determinant regression of any plant of the class (ShiftRegression) and the observer built on it."""

import numpy as np
import pytest

from obsfmu.observers.block import Segment
from obsfmu.observers.gpebo import GeneratorModel, GpeboObserver
from obsfmu.observers.gpebo.regression import ExampleRegression, ShiftRegression, regression_for
from obsfmu.plants.gpebo import EXAMPLE, GeneratorPlant, example_model


def record(model, gammas, xi0, x0, samples=80, noise=0.0, seed=0):
    """u, y of the plant (sizes of ``model``, generators [0, ..., 0, g]) driven by sin k + sin 2k."""
    vectors = [np.r_[np.zeros(size - 1), g] for size, g in zip([s for s in model.sizes if s], gammas)]
    plant = GeneratorPlant(model, vectors[0], vectors[1], xi0[0], xi0[1], x0, 1.0,
                           *(vectors[2:3] + list(xi0[2:3])) if len(vectors) > 2 else ())
    u = np.sin(np.arange(samples)) + np.sin(2.0 * np.arange(samples))
    y, x = [], []
    for k in range(samples):
        y.append(plant.x[0])
        x.append(plant.x.copy())
        plant.advance(k, 1.0, {"u": Segment.hold([u[k]])})
    rng = np.random.default_rng(seed)
    return u, np.array(y) + noise * rng.standard_normal(samples), np.array(x)


def residual(regression, u, y, gammas) -> float:
    """Largest |zeta - rho^T sigma(gamma)| / |(zeta, rho)| over the record."""
    sigma, worst, w = regression.sigma(*gammas), 0.0, regression.window
    for k in range(w - 1, len(y)):
        zeta, rho = regression.row(u[k - w + 1:k + 1], y[k - w + 1:k + 1])
        worst = max(worst, abs(zeta - rho @ sigma) / np.hypot(zeta, np.linalg.norm(rho)))
    return worst


def test_on_the_example_it_is_the_example_regression_up_to_normalisation():
    model = example_model()
    assert isinstance(regression_for(model), ExampleRegression)
    shift = ShiftRegression(model)
    assert (shift.p, shift.window, shift.names) == (5, 7, ("gamma_beta", "gamma_theta"))
    u, y, _ = record(model, (-1.0, 1.0), (EXAMPLE["xi_beta0"], EXAMPLE["xi_theta0"]), EXAMPLE["x0"], 40)
    assert residual(shift, u, y, (-1.0, 1.0)) < 1e-15
    assert residual(ExampleRegression(model), u, y, (-1.0, 1.0)) < 1e-15
    assert residual(shift, u, y, (-1.0, 0.9)) > 1e-3          # a wrong gamma violates it
    np.testing.assert_allclose(shift.gammas(shift.sigma(-0.7, 0.4)), [-0.7, 0.4], rtol=1e-15)


@pytest.mark.parametrize("sizes, gammas", [
    ((3, 3, 0), (-1.0, 1.0)),            # the worked example's generators, n = 3
    ((1, 3, 0), (0.9, -1.0)),            # D = 3: g_beta enters as g_beta^3, recovered by the real cube root
    ((2, 2, 2), (-1.0, 1.0, 0.8)),       # with a delta generator: 23 unknowns
])
def test_the_regression_holds_exactly_on_the_plant(sizes, gammas):
    l, m, r = sizes
    H = np.zeros((3, m))
    H[1, 0] = 1.0
    model = GeneratorModel.checked(3, np.eye(l)[0], H, np.eye(3, r)[[2, 0, 1]] if r else None,
                                   lambda y: np.array([0.0, np.tanh(y), 0.0]))
    regression = ShiftRegression(model)
    xi0 = [np.linspace(1.0, 0.3, l), np.linspace(0.5, -0.4, m), np.linspace(0.2, 0.1, r)][:3 if r else 2]
    u, y, _ = record(model, gammas, xi0, [0.3, -0.2, 0.1])
    assert residual(regression, u, y, gammas) < 1e-12
    np.testing.assert_allclose(regression.gammas(regression.sigma(*gammas)), gammas, rtol=1e-14)


def test_observer_of_a_third_order_plant_converges_and_certifies_only_exact_data():
    model = GeneratorModel.checked(3, [1.0, 0.0, 0.0], np.eye(3)[:, [1]] @ np.eye(3)[[0]], None,
                                   lambda y: np.array([0.0, np.tanh(y), 0.0]))
    xi0, x0 = ([1.0, 0.5, -0.3], [0.5, -0.4, 0.8]), [0.3, -0.2, 0.1]
    for noise, restart_tol in ((0.0, 1e-11), (1e-8, 1e-4)):
        u, y, x = record(model, (-1.0, 1.0), xi0, x0, 60, noise)
        observer = GpeboObserver(model, 1.0, restart_tol=restart_tol)
        flags, errors = [], []
        for k in range(60):
            out = observer.outputs(k, {})
            flags.append(out["converged"][0])
            errors.append(np.max(np.abs(out["x_hat"] - x[k])))
            observer.advance(k, 1.0, {"u": Segment.hold([u[k]]), "y": Segment.hold([y[k]])})
        if noise:
            assert max(flags) == 0 and errors[-1] < 1e-4     # estimates near, but never certified
        else:
            assert flags[-1] == 1 and errors[-1] < 1e-11
            assert np.all(np.array(errors)[np.array(flags) > 0] < 1e-6)
