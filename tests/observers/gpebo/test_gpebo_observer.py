"""Paper 000 (issue 7): plant, derived regression and GPEBO + DREM observer against independent loops.

The truth comes from ``fmus/scenarios/discrete_gpebo/reference.py``, a plain discrete loop of the example written
without importing the project.  Numbers in comments were measured with the defaults.
"""

import numpy as np
import pytest

from obsfmu.observers.block import Segment
from obsfmu.observers.checks import ParameterError, SignalError
from obsfmu.observers.gpebo import ExampleRegression, GeneratorModel, GpeboFilters, GpeboObserver, generator_matrix
from obsfmu.plants.gpebo import EXAMPLE, GeneratorPlant, example_model
from obsfmu.fmus.scenarios.discrete_gpebo import reference as ref

SINES = ref.INPUTS["sines"]


def plant_data(u, g_b=-1.0, g_t=1.0, xi_b0=EXAMPLE["xi_beta0"], xi_t0=EXAMPLE["xi_theta0"], x0=EXAMPLE["x0"]):
    return ref.simulate_plant(g_b, g_t, xi_b0, xi_t0, x0, u)


def observe(u, y, **options):
    """Feed the observer block with u(k), y(k); its outputs at samples 0 .. K."""
    observer = GpeboObserver(example_model(), 1.0, **options)
    rows = []
    for k in range(len(u) + 1):
        rows.append(observer.outputs(float(k), {}))
        if k < len(u):
            observer.advance(float(k), 1.0, {"u": Segment.hold([u[k]]), "y": Segment.hold([y[k]])})
    return {name: np.array([row[name] for row in rows]) for name in rows[0]}, observer


def settled(error, tolerance) -> int:
    """First sample after which ``error`` (max over columns) stays below ``tolerance``."""
    error = np.abs(error).reshape(len(error), -1).max(axis=1)
    bad = np.nonzero(~(error < tolerance))[0]
    return 0 if bad.size == 0 else int(bad[-1] + 1)


# ---------------------------------------------------------------------------------------- regression
@pytest.mark.parametrize("name", ["sines", "constant", "exponential"])
def test_derived_regression_holds_on_independent_plant_data(name):
    rng = np.random.default_rng(7)
    for _ in range(5):
        g_b, g_t = rng.uniform(-1.2, -0.3), rng.uniform(0.3, 1.2) * rng.choice([-1, 1])
        u = ref.INPUTS[name](np.arange(40.0))
        x, *_ = plant_data(u, g_b, g_t, rng.uniform(-1, 1, 2), rng.uniform(-1, 1, 2), rng.uniform(-1, 1, 2))
        y = x[:, 0]
        regression = ExampleRegression(example_model())
        sigma = regression.sigma(g_b, g_t)
        for k in range(6, 40):
            zeta, rho = regression.row(u[k - 6:k + 1], y[k - 6:k + 1])
            scale = max(1.0, abs(zeta), float(np.abs(rho * sigma).max()))
            assert abs(zeta - rho @ sigma) < 1e-13 * scale, k
            # and the determinant it comes from vanishes (reference's own matrix)
            assert abs(np.linalg.det(ref.regression_matrix(u, y, k, g_b, g_t))) < 1e-12 * scale


def test_sigma_left_inverse_and_generator_form():
    for g_b, g_t in [(-1.0, 1.0), (0.3, -2.0), (-0.9, 0.8)]:
        np.testing.assert_allclose(ExampleRegression.gammas(ExampleRegression.sigma(g_b, g_t)), [g_b, g_t],
                                   rtol=1e-15)
    np.testing.assert_array_equal(generator_matrix([0.0, -1.0]), [[0.0, 1.0], [-1.0, 0.0]])
    Gamma = generator_matrix([0.5, -0.2, 0.1])                # companion form: z^3 - 0.5 z^2 + 0.2 z - 0.1
    np.testing.assert_allclose(np.poly(Gamma), [1.0, -0.5, 0.2, -0.1], atol=1e-14)


def test_constant_input_orbit_has_regressions_of_rank_1_and_2():
    """u = 5: the plant settles on a 4-periodic orbit; the gamma rows have rank 1, the eta rows rank 2 of 4."""
    u = np.full(200, 5.0)
    x, *_ = plant_data(u)
    np.testing.assert_allclose(x[196:200], x[192:196], atol=1e-12)       # period 4
    np.testing.assert_allclose(x[198], -x[196], atol=1e-12)              # odd symmetry y(k+2) = -y(k)
    regression = ExampleRegression(example_model())
    rows = np.array([regression.row(u[k - 6:k + 1], x[k - 6:k + 1, 0])[1] for k in range(150, 200)])
    singular = np.linalg.svd(rows / np.linalg.norm(rows, axis=1)[:, None], compute_uv=False)
    assert singular[0] > 1 and singular[1] < 1e-12                      # measured 10, 7e-16


# ---------------------------------------------------------------------------------------- plant
def test_plant_block_matches_the_independent_loop_and_is_bounded():
    rng = np.random.default_rng(3)
    u = SINES(np.arange(4000.0))
    for _ in range(5):
        xi_b0, xi_t0, x0 = rng.uniform(-1, 1, 2), rng.uniform(-1, 1, 2), rng.uniform(-1, 1, 2)
        x, beta, theta1, _ = plant_data(u, -1.0, 1.0, xi_b0, xi_t0, x0)
        plant = GeneratorPlant(example_model(), [0, -1], [0, 1], xi_b0, xi_t0, x0, 1.0)
        for k in range(len(u)):
            out = plant.outputs(k, {})
            assert np.array_equal(out["x"], x[k]) and out["beta"][0] == beta[k] and out["theta"][0] == theta1[k]
            assert out["theta"][1] == 0.0
            plant.advance(float(k), 1.0, {"u": Segment(np.array([u[k]]), np.array([99.0]))})  # slope ignored
        # generators: beta 4-periodic, theta1 2-periodic; |x1| <= max|beta| max|u| + max|theta1|
        np.testing.assert_array_equal(beta[4:], beta[:-4])
        np.testing.assert_array_equal(theta1[2:], theta1[:-2])
        bound = np.abs(beta).max() * np.abs(u).max() + np.abs(theta1).max()
        assert np.abs(x[1:]).max() <= bound


def test_general_plant_with_disturbance_generator():
    """n = 3, generators of sizes 3, 2, 1: x(k+1) = A x + e_3 beta u + theta * f(y) + delta, by hand."""
    f = lambda y: np.array([np.sin(y), np.cos(y), y / (1 + y * y)])  # noqa: E731
    H_theta = np.array([[1.0, 0.5], [0.0, 1.0], [0.2, 0.0]])
    model = GeneratorModel.checked(3, [1.0, 0.0, 0.5], H_theta, [[0.3], [0.0], [1.0]], f)
    gb, gt, gd = [0.1, -0.5, 0.2], [0.0, 0.9], [0.95]
    plant = GeneratorPlant(model, gb, gt, [1, 0.2, -0.3], [0.4, 0.1], [0.5, 0.6, -0.7], 0.1, gd, [1.0])
    x, xb, xt, xd = np.array([0.5, 0.6, -0.7]), np.array([1, 0.2, -0.3]), np.array([0.4, 0.1]), np.array([1.0])
    for k in range(30):
        u = np.sin(0.3 * k)
        out = plant.outputs(0.1 * k, {})
        np.testing.assert_allclose(out["x"], x, rtol=1e-14, atol=1e-14)
        np.testing.assert_allclose(out["delta"], [0.3 * xd[0], 0.0, xd[0]], rtol=1e-14)
        beta = xb[0] + 0.5 * xb[2]
        x = (np.array([x[1], x[2], 0.0]) + np.array([0, 0, beta * u]) + (H_theta @ xt) * f(x[0])
             + np.array([0.3, 0.0, 1.0]) * xd[0])
        xb = np.array([gb[0] * xb[0] + xb[1], gb[1] * xb[0] + xb[2], gb[2] * xb[0]])
        xt, xd = np.array([gt[0] * xt[0] + xt[1], gt[1] * xt[0]]), gd[0] * xd
        plant.advance(0.1 * k, 0.1, {"u": Segment.hold([u])})


def test_plant_refuses_bad_configuration_and_other_steps():
    model = example_model()
    good = dict(gamma_beta=[0, -1], gamma_theta=[0, 1], xi_beta0=[1, 0], xi_theta0=[1, 0], x0=[0, 0], Ts=1.0)
    with pytest.raises(ParameterError, match="gamma_theta: expected 2 entries"):
        GeneratorPlant(model, **{**good, "gamma_theta": [1.0]})
    with pytest.raises(ParameterError, match=r"x0: entry \(2,\) is not finite"):
        GeneratorPlant(model, **{**good, "x0": [0.0, np.nan]})
    with pytest.raises(ParameterError, match="Ts: must be > 0"):
        GeneratorPlant(model, **{**good, "Ts": 0.0})
    with pytest.raises(ParameterError, match="H_theta: expected 2 rows"):
        GeneratorModel.checked(2, [1, 0], [[1, 0]])
    plant, whole = GeneratorPlant(model, **good), GeneratorPlant(model, **good)
    plant.advance(0.0, 0.5, {"u": Segment.hold([1.0])})          # sampled at t = 0, updated at t = 1 (issue 36)
    np.testing.assert_array_equal(plant.x, [0.0, 0.0])
    plant.advance(0.5, 0.5, {"u": Segment.hold([7.0])})          # no instant in [0.5, 1): u(0) = 1 was latched
    whole.advance(0.0, 1.0, {"u": Segment.hold([1.0])})
    np.testing.assert_array_equal(plant.x, whole.x)
    np.testing.assert_array_equal(plant.xi, whole.xi)
    plant = GeneratorPlant(model, **good)
    with pytest.raises(SignalError, match="u: non-finite"):
        plant.advance(0.0, 1.0, {"u": Segment.hold([np.inf])})
    bad = GeneratorPlant(GeneratorModel.checked(2, [1, 0], [[1, 0], [0, 0]], None, lambda y: np.log(y)),
                         **{**good, "x0": [-1.0, 0.0]})
    before = bad.get_state()
    with pytest.raises(SignalError, match="f: f"), np.errstate(invalid="ignore"):
        bad.advance(0.0, 1.0, {"u": Segment.hold([1.0])})
    np.testing.assert_array_equal(bad.x, before["x"])
    np.testing.assert_array_equal(bad.xi, before["xi"])


# ---------------------------------------------------------------------------------------- observer
def test_sines_40_random_initial_states_exact_within_21_samples():
    """u = sin t + sin 2t, Ts = 1: gamma to 1e-6 within 13 samples, x within 20, both below 1e-9 by 21."""
    rng = np.random.default_rng(2024)
    K = 60
    u = SINES(np.arange(float(K)))
    worst = {"gamma": 0, "x": 0, "x9": 0, "excited": 0}
    for _ in range(40):
        x, beta, theta1, xi = plant_data(u, -1.0, 1.0, *rng.uniform(-1, 1, (3, 2)))
        out, _ = observe(u, x[:-1, 0])
        gamma_error = out["gamma_hat"] - [-1.0, 1.0]
        x_error = out["x_hat"] - x
        worst["gamma"] = max(worst["gamma"], settled(gamma_error, 1e-6))
        worst["x"] = max(worst["x"], settled(x_error, 1e-6))
        worst["x9"] = max(worst["x9"], settled(np.hstack([x_error, gamma_error]), 1e-9))
        excited = out["excited"][:, 0] > 0.5
        first = int(np.argmax(excited))
        assert excited[first:].all()                                     # once excited, it stays so
        assert np.abs(x_error[excited]).max() < 1e-9                     # the flag never vouches for a bad x_hat
        worst["excited"] = max(worst["excited"], first)
        np.testing.assert_allclose(out["beta_hat"][-1, 0], beta[-1], atol=1e-9)
        np.testing.assert_allclose(out["theta_hat"][-1], [theta1[-1], 0.0], atol=1e-9)
        # eta_hat is xi at the last restart of the filters
        t0 = int(out["restart_time"][-1, 0])
        np.testing.assert_allclose(out["eta_hat"][-1], xi[t0], atol=1e-9)
    assert worst == {"gamma": 13, "x": 20, "x9": 21, "excited": 21}      # measured over the 40 states


def test_observer_and_independent_observer_agree_once_converged():
    u = SINES(np.arange(80.0))
    x, *_ = plant_data(u)
    out, _ = observe(u, x[:-1, 0])
    x_ref, gamma_ref, xi_ref = ref.run_observer(u, x[:-1, 0], gain=1e-8, restart_tol=1e-11)
    # both are exact up to their DREM noise floors (measured 3.1e-10 and 3.1e-10, gamma 4e-15)
    assert np.abs(x_ref[25:] - x[25:]).max() < 1e-9
    assert np.abs(out["x_hat"][25:] - x_ref[25:]).max() < 1e-9
    assert np.abs(out["gamma_hat"][15:] - gamma_ref[15:]).max() < 1e-12


def test_constant_input_is_flagged_and_unrecoverable_on_its_orbit_even_with_true_gamma():
    u = np.full(260, 5.0)
    x, *_ = plant_data(u)
    out, observer = observe(u[:60], x[:60, 0])
    assert not out["excited"].any()
    assert out["nu_gamma"][-1, 0] > 0.99                                  # Delta = 0: nothing learnt
    assert np.abs(out["gamma_hat"][-1] - [-1, 1]).max() > 0.1
    # start on the 4-periodic orbit (same generator phase: 200 = 0 mod 4), observer given the true gamma
    x_orbit, *_ = plant_data(u[:60], x0=x[200])
    out, _ = observe(u[:60], x_orbit[:-1, 0], gamma_hat0=(-1.0, 1.0))
    assert not out["excited"].any()
    assert out["nu_eta"].min() == 1.0                                     # eta regression: rank 2 of 4, Delta = 0
    assert np.abs(out["x_hat"][-1] - x_orbit[-1]).max() > 1.0


def test_decaying_input_excites_only_a_few_samples():
    u = ref.INPUTS["exponential"](np.arange(60.0))
    x, *_ = plant_data(u)
    _, observer = observe(u[:10], x[:10, 0])
    deltas = []
    for k in range(10, 40):
        observer.advance(float(k), 1.0, {"u": Segment.hold([u[k]]), "y": Segment.hold([x[k, 0]])})
        deltas.append(abs(observer.gamma_drem.delta))
    deltas = np.array(deltas)
    assert deltas.max() < 1e-6 and np.all(deltas[5:] < 1e-10)             # measured 1.3e-7, then ~10x smaller a sample
    assert observer.nu_gamma > 0.99 and not observer.excited


def test_resonant_sampling_destroys_the_excitation():
    """Ts = pi/2: u(k) = sin(k pi/2) + sin(k pi) vanishes every other sample, against the 4-periodic beta."""
    u = SINES(np.pi / 2 * np.arange(60.0))
    x, *_ = plant_data(u)
    out, _ = observe(u, x[:-1, 0])
    assert not out["excited"].any()
    assert np.abs(out["gamma_hat"][-1] - [-1, 1]).max() > 0.1             # measured 0.35


def test_observer_state_is_restored_after_a_refused_sample(monkeypatch):
    u = SINES(np.arange(30.0))
    x, *_ = plant_data(u)
    _, observer = observe(u[:20], x[:20, 0])
    before = observer.get_state()
    with pytest.raises(SignalError, match="y: non-finite"):
        observer.advance(20.0, 1.0, {"u": Segment.hold([u[20]]), "y": Segment.hold([np.nan])})
    np.testing.assert_array_equal(observer.get_state()["window"], before["window"])

    def fail(*args):
        raise RuntimeError("sabotage after both DREM updates")

    monkeypatch.setattr(GpeboFilters, "advance", fail)                   # the sample fails half way
    with pytest.raises(RuntimeError, match="sabotage"):
        observer.advance(20.0, 1.0, {"u": Segment.hold([u[20]]), "y": Segment.hold([x[20, 0]])})
    after = observer.get_state()
    np.testing.assert_array_equal(after["window"], before["window"])
    np.testing.assert_array_equal(after["gamma_drem"]["theta_hat"], before["gamma_drem"]["theta_hat"])
    np.testing.assert_array_equal(after["eta_drem"]["theta_hat"], before["eta_drem"]["theta_hat"])
    assert (after["samples"], after["nu_gamma"], after["nu_eta"]) == (
        before["samples"], before["nu_gamma"], before["nu_eta"])
    monkeypatch.undo()
    observer.advance(20.0, 1.0, {"u": Segment.hold([u[20]]), "y": Segment.hold([x[20, 0]])})
    assert observer.samples == before["samples"] + 1


def test_observer_refuses_bad_configuration():
    model = example_model()
    with pytest.raises(ParameterError, match="gamma_hat0: gamma_beta"):
        GpeboObserver(model, 1.0, gamma_hat0=(0.0, 1.0))
    with pytest.raises(ParameterError, match="k_gamma: must be > 0"):
        GpeboObserver(model, 1.0, k_gamma=-1.0)
    with pytest.raises(ParameterError, match="eta_hat0: expected 4 entries"):
        GpeboObserver(model, 1.0, eta_hat0=[0.0, 0.0])
    with pytest.raises(ParameterError, match="model: the input-output regression is derived for paper 000"):
        ExampleRegression(GeneratorModel.checked(2, [1.0, 0.0], [[1.0, 0.0], [0.0, 1.0]]))
    with pytest.raises(ParameterError, match="h_beta: is zero, so the beta generator does not reach the output"):
        GpeboObserver(GeneratorModel.checked(2, [0.0, 0.0], [[1.0, 0.0], [0.0, 1.0]]), 1.0)
    with pytest.raises(ParameterError, match=r"h_beta: the regression shifts by D = lcm .* \[3, 2\] = 6 samples"):
        GpeboObserver(GeneratorModel.checked(2, [1.0, 0.0, 0.0], [[1.0, 0.0], [0.0, 0.0]]), 1.0,
                      gamma_hat0=(-0.5, 0.5))
    with pytest.raises(ParameterError, match="gamma_beta: must be nonzero"):
        ExampleRegression.sigma(0.0, 1.0)
    observer = GpeboObserver(model, 1.0)
    with pytest.raises(SignalError, match="y: non-finite"):
        observer.advance(0.0, 1.0, {"u": Segment.hold([1.0]), "y": Segment.hold([np.nan])})
    assert observer.samples == 0 and observer.filters.age == 0
