"""Paper 000 (issue 7) through FMUs: scenario ``discrete-gpebo`` against the independent discrete loops.

The reference (``fmus/scenarios/discrete_gpebo/reference.py``) imports nothing from the project.
"""

import numpy as np
import pytest
from fmpy.validation import validate_fmu

from obsfmu.fmus.cli import main as cli
from obsfmu.fmus.master import SimulationError
from obsfmu.fmus.scenarios import ensure_fmus, get, run
from obsfmu.fmus.scenarios.discrete_gpebo import plant_residual
from obsfmu.fmus.scenarios.discrete_gpebo import reference as ref

PAPER_STATE = dict(xi_b0=[1.0, 0.5], xi_t0=[0.5, -0.4], x0=[0.3, -0.2])   # the scenario's defaults
SILENCE = [("source", "amplitude[1]", 0.0), ("source", "amplitude[2]", 0.0)]


@pytest.fixture(scope="module")
def fmus(build_dir):
    return ensure_fmus(get("discrete-gpebo"), build_dir)


def simulate(build_dir, fmus, **options):
    return run("discrete-gpebo", build_dir, **options)


def independent(u, g_b=-1.0, g_t=1.0, xi_b0=PAPER_STATE["xi_b0"], xi_t0=PAPER_STATE["xi_t0"], x0=PAPER_STATE["x0"]):
    return ref.simulate_plant(g_b, g_t, xi_b0, xi_t0, x0, u)


def first_sample_below(error, tolerance) -> int:
    error = np.abs(error).reshape(len(error), -1).max(axis=1)
    bad = np.nonzero(~(error < tolerance))[0]
    return 0 if bad.size == 0 else int(bad[-1] + 1)


def test_fmus_are_valid_and_say_they_are_discrete(fmus):
    for path in fmus.values():
        assert validate_fmu(str(path)) == [], path
    from fmpy import read_model_description
    for name in ("gpebo_plant", "gpebo_observer"):
        description = read_model_description(str(fmus[name]))
        assert "sampled at t = k Ts whatever the communication step" in description.description
        names = {v.name for v in description.modelVariables}
        assert {"Ts", "u_interpolation"} <= names
    plant = {v.name for v in read_model_description(str(fmus["gpebo_plant"])).modelVariables}
    assert {"gamma_beta[2]", "gamma_theta[2]", "xi_beta0[1]", "xi_theta0[2]", "x0[2]", "H_theta[1,1]"} <= plant
    observer = {v.name for v in read_model_description(str(fmus["gpebo_observer"])).modelVariables}
    assert {"x_hat[2]", "gamma_hat[2]", "eta_hat[4]", "beta_hat", "theta_hat[2]", "excited"} <= observer


def test_default_run_matches_the_independent_loops_and_converges(build_dir, fmus, tmp_path):
    csv, png = tmp_path / "run.csv", tmp_path / "run.png"
    assert cli.main(["run", "discrete-gpebo", "--build-dir", str(build_dir), "--csv", str(csv),
                     "--plot", str(png)]) == 0
    assert png.stat().st_size > 10_000
    result, summary = simulate(build_dir, fmus)
    k = np.arange(41.0)
    u = ref.INPUTS["sines"](k)
    np.testing.assert_allclose(result.time, k, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(result["source.y"], u)
    x, beta, theta1, _ = independent(u[:-1])
    # the co-simulated plant is the plain discrete loop, to round-off
    assert np.abs(result.vector("plant.x") - x).max() <= 1e-14
    assert np.abs(result["plant.beta"] - beta).max() == 0.0
    assert np.abs(result.vector("plant.theta")[:, 0] - theta1).max() == 0.0
    assert plant_residual(result) <= 1e-15
    # acceptance: gamma and x to 1e-6 (measured: 12 and 18 samples), excited from sample 18
    gamma_error = result.vector("observer.gamma_hat") - [-1.0, 1.0]
    x_error = result.vector("observer.x_hat") - x
    assert first_sample_below(gamma_error, 1e-6) == 12
    assert first_sample_below(x_error, 1e-6) == 18
    assert first_sample_below(x_error, 1e-9) == 18 and np.abs(x_error[18:]).max() < 3e-10   # measured 1.5e-10
    assert summary.metrics["first_excited_sample"] == 18 and summary.metrics["excited_at_end"] == 1.0
    # and the independent observer agrees once both have converged
    x_ref, gamma_ref, _ = ref.run_observer(u[:-1], x[:-1, 0], gain=1e-8, restart_tol=1e-11)
    assert np.abs(result.vector("observer.x_hat")[20:] - x_ref[20:]).max() < 1e-9
    assert np.abs(result.vector("observer.gamma_hat")[14:] - gamma_ref[14:]).max() < 1e-12


def test_sampled_inputs_are_taken_at_the_step_start_for_every_order_and_coupling(build_dir, fmus):
    results = {(order, coupling): simulate(build_dir, fmus, order=order, coupling=coupling)[0]
               for order in ("jacobi", "gauss-seidel") for coupling in ("linear", "hold")}
    reference = results["jacobi", "linear"].values
    for key in [("jacobi", "hold"), ("gauss-seidel", "linear")]:
        np.testing.assert_array_equal(results[key].values, reference)
    # Gauss-Seidel with held inputs hands the discrete blocks u(k+1): documented as wrong
    assert plant_residual(results["gauss-seidel", "hold"]) > 1.0


def test_other_gamma_and_initial_states_set_on_the_plant(build_dir, fmus):
    overrides = [("plant", "gamma_beta[2]", -0.9), ("plant", "gamma_theta[2]", 0.8),
                 ("plant", "xi_beta0[1]", 0.3), ("plant", "xi_theta0[2]", 0.9), ("plant", "x0[1]", -1.0)]
    result, summary = simulate(build_dir, fmus, overrides=overrides)
    u = ref.INPUTS["sines"](np.arange(40.0))
    x, *_ = independent(u, -0.9, 0.8, [0.3, 0.5], [0.5, 0.9], [-1.0, -0.2])
    assert np.abs(result.vector("plant.x") - x).max() <= 1e-14
    gamma_error = result.vector("observer.gamma_hat") - [-0.9, 0.8]
    x_error = result.vector("observer.x_hat") - x
    assert first_sample_below(gamma_error, 1e-6) <= 13 and first_sample_below(x_error, 1e-6) <= 20
    assert np.abs(gamma_error[-1]).max() < 1e-12 and np.abs(x_error[-1]).max() < 1e-9
    assert summary.metrics["excited_at_end"] == 1.0


@pytest.mark.parametrize("case, overrides", [
    ("constant", SILENCE + [("source", "offset", 5.0)]),
    ("exponential", SILENCE + [("source", "exp_amplitude", 1.0), ("source", "exp_rate", 0.5)]),
])
def test_non_exciting_inputs_are_flagged(build_dir, fmus, case, overrides):
    result, summary = simulate(build_dir, fmus, overrides=overrides)
    np.testing.assert_allclose(result["source.y"], ref.INPUTS[case](result.time), rtol=1e-15)
    assert not result["observer.excited"].any()
    assert result["observer.nu_gamma"][-1] > 0.99
    assert np.abs(result.vector("observer.gamma_hat")[-1] - [-1.0, 1.0]).max() > 0.1
    assert any(line.startswith("WARNING: the observer reports excited = 0") for line in summary.lines)


def test_resonant_sampling_period_through_the_fmus(build_dir, fmus):
    Ts = np.pi / 2
    overrides = [("plant", "Ts", Ts), ("observer", "Ts", Ts)]
    result, summary = simulate(build_dir, fmus, step=Ts, stop_time=40 * Ts, overrides=overrides)
    u = ref.INPUTS["sines"](Ts * np.arange(40.0))
    x, *_ = independent(u)
    assert np.abs(result.vector("plant.x") - x).max() <= 1e-14
    assert not result["observer.excited"].any()
    assert summary.metrics["gamma_samples_to_tolerance"] == np.inf


def test_any_step_samples_at_the_sample_instants(build_dir, fmus):
    """Issue 36: the FMUs refused any step but Ts.  At steps that divide Ts every instant is a communication
    point: plant and observer at t = k Ts equal the one-sample-per-step run to round-off, held in between."""
    whole, _ = simulate(build_dir, fmus, stop_time=20.0)
    for step, per_sample in ((0.5, 2), (0.25, 4)):
        finer, _ = simulate(build_dir, fmus, step=step, stop_time=20.0)
        for column in ("plant.x[1]", "plant.x[2]", "observer.x_hat[1]", "observer.gamma_hat[1]"):
            np.testing.assert_allclose(finer[column][::per_sample], whole[column], rtol=1e-12, atol=1e-14,
                                       err_msg=f"{column} at h = {step}")
            held = finer[column][:-1].reshape(-1, per_sample)        # constant between the instants
            assert np.all(held == held[:, :1]), column


def test_bad_parameters_are_clear_errors(build_dir, fmus):
    with pytest.raises(SimulationError, match="gamma_hat0: gamma_beta"):
        simulate(build_dir, fmus, overrides=[("observer", "gamma_hat0[1]", 0.0)])
