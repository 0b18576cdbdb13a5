"""Paper 003 through FMUs: validity, the acceptance run, the monolithic reference, other plants, noise.

Every number in a comment was measured with the scenario defaults (Gauss-Seidel, step 1e-3 s,
linear coupling: the observer gets ``y`` interpolated across each step).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu

from obsfmu.fmus.master import SimulationError
from obsfmu.fmus.scenarios import ensure_fmus, get, parse_overrides, run
from obsfmu.fmus.scenarios.uio_ftdrem import REFERENCE, deviation_from_reference, errors, is_default, summarize
from obsfmu.observers.uio.settling import SETTLED, TIMED_OUT

NAME = "uio-ftdrem"


@pytest.fixture(scope="module")
def fmus(build_dir):
    return ensure_fmus(get(NAME), build_dir)


@pytest.fixture(scope="module")
def default_run(fmus, build_dir):
    result, summary = run(NAME, build_dir)
    return result, summary


def last_fifth(result):
    return result.time >= 0.8 * result.time[-1] - 1e-9


def test_fmus_are_valid_and_name_their_variables(fmus):
    for path in fmus.values():
        assert validate_fmu(str(path)) == [], path
    plant = {v.name: v for v in read_model_description(str(fmus["uio_ftdrem_plant"])).modelVariables}
    for name in ["amplitude", "omega", "phase", "x0[1]", "x0[2]", "xi0[2]", "noise_std", "y", "x[2]",
                 "theta[2]", "f", "f_omega"]:
        assert name in plant, name
    assert plant["omega"].unit == "rad/s" and plant["amplitude"].causality == "parameter"
    observer = {v.name: v for v in read_model_description(str(fmus["uio_ftdrem_observer"])).modelVariables}
    for name in ["r", "L[1]", "z0[2]", "gamma[2]", "mu", "rates2[2]", "y", "y_interpolation", "x_hat[2]",
                 "x_tilde0_hat[1]", "xi0_hat[2]", "omega_hat", "f_hat", "identified[4]", "t_identified[1]"]:
        assert name in observer, name
    assert float(observer["L[2]"].start) == pytest.approx(0.075)
    assert observer["t_identified[1]"].unit == "s"


def test_acceptance_of_the_paper_example(default_run):
    result, summary = default_run
    e = errors(result)
    last = last_fifth(result)
    assert np.max(np.abs(e["omega"][last])) < 1e-4            # 3.3e-9
    assert np.max(np.abs(e["xi0"][last])) < 1e-4               # 3.4e-8 (issue: 1e-3, 1e-4 attainable)
    assert np.max(np.abs(e["f"][last])) < 2e-3                 # 5.8e-7
    assert np.max(e["x_relative"][last]) < 1e-5                # 1.2e-7
    at = result.index_at(0.1)
    assert np.max(np.abs(e["x_tilde0"][at:])) < 1e-6           # exact from the switch on: 1.8e-13
    status = result.vector("observer.identified")[-1]
    times = result.vector("observer.t_identified")[-1]
    np.testing.assert_array_equal(status, [SETTLED] * 4)
    assert times[0] < 0.1 and times[3] < 10.0                  # 0.056, 6.55, 7.05, 7.56 s
    assert summary.metrics["x_relative_error_last20"] == pytest.approx(np.max(e["x_relative"][last]))


def test_cosimulation_agrees_with_the_monolithic_radau_reference(default_run):
    """Reference: fmus/scenarios/uio_ftdrem/reference.py (Radau, rtol 1e-10), stored in the scenario folder."""
    result, _ = default_run
    assert REFERENCE.exists() and is_default(result)
    whole = deviation_from_reference(result, start=0.0)
    assert whole["plant.x"] < 1e-9                              # 8.5e-11 (RK4 in the plant FMU vs Radau)
    assert deviation_from_reference(result, start=0.1)["observer.x_tilde0_hat"] < 1e-11  # 2.2e-13
    # during the transients the sampled and the continuous DREM laws take different paths
    # (omega: 4.8e-4 on [3, 20] s); once converged both sit on the truth:
    late = deviation_from_reference(result, start=16.0)
    assert late["observer.omega_hat"] < 1e-7                   # 3.1e-9
    assert late["observer.xi0_hat"] < 1e-7                     # 7.3e-9
    assert late["observer.f_hat"] < 2e-6                       # 4.3e-7
    assert late["observer.x_hat"] < 2e-6                       # 5.1e-7


def test_reference_module_reproduces_the_whole_stored_reference_and_finds_the_stage_times(default_run):
    """All 20 s of the independent reference (~55 s CPU): it finds its own stage times, close to
    those of the co-simulation, and reproduces every column of the stored ``reference.csv``.

    Tolerance: ``1e-8 (1 + |stored|)``; the estimates reach 1e2 (``xi0_hat``) and 1e5 (``f_hat``)
    in the transients, where the solver's rtol = 1e-10 is what two correct solutions share.
    ``f_hat`` amplifies the error of the stage-3 FT-DREM state by ``1 / (1 - mu) = 50`` and by
    ``|((j w_hat + l2) / l2)^3|``: there two Radau solutions at rtol 1e-10 and 1e-12 differ by
    8.6e-6 at |f_hat| = 1.5e5 (t = 0.1 s), so ``f_hat`` gets ``1e-6 (1 + |stored|)`` before
    stage 4 has been identified and 1e-8 after it (t >= 8 s).
    """
    from obsfmu.fmus.result import Result
    from obsfmu.fmus.scenarios.uio_ftdrem import reference

    stored = Result.from_csv(REFERENCE)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        fresh = reference.simulate(stored.time)
    cosim = default_run[0].vector("observer.t_identified")[-1]
    # measured: reference 6.530, 7.030, 7.543 s; co-simulation 6.547, 7.046, 7.559 s
    np.testing.assert_allclose(fresh["stage_times"], cosim[1:], atol=0.05)
    late = stored.time >= 8.0
    # measured max |fresh - stored| / (1 + |stored|): x 1.9e-11, x_tilde0_hat 2.6e-13, xi0_hat 1.1e-9,
    # omega_hat 6.8e-10, f_hat 6.5e-8 (t = 2.61 s; 1.8e-9 absolute from 8 s), x_hat 1.5e-10
    for key, column, tolerance in (("x", "plant.x", 1e-8), ("x_tilde0_hat", "observer.x_tilde0_hat", 1e-8),
                                   ("xi0_hat", "observer.xi0_hat", 1e-8), ("omega_hat", "observer.omega_hat", 1e-8),
                                   ("f_hat", "observer.f_hat", 1e-6), ("x_hat", "observer.x_hat", 1e-8)):
        expected = stored.vector(column)
        deviation = np.abs(fresh[key] - expected) / (1.0 + np.abs(expected))
        assert deviation.max() < tolerance, (key, deviation.max())
        assert np.abs(fresh[key] - expected)[late].max() < 1e-8, key


def test_reference_right_hand_sides_agree():
    """The reference computes one state on Python floats and stacks (its Jacobian) with numpy: the
    same equations, in every mode (which stages adapt, which switched, stage 4 on or off)."""
    from obsfmu.fmus.scenarios.uio_ftdrem import reference

    model = reference.Reference(**reference.PAPER, **reference.TUNING)
    rng = np.random.default_rng(3)
    for _ in range(32):
        model.adapt = {stage: bool(rng.integers(2)) for stage in reference.STAGES}
        model.switched = {stage: bool(rng.integers(2)) for stage in reference.STAGES}
        model.stage4, model.K = bool(rng.integers(2)), rng.normal(size=2)
        states, t = rng.normal(size=(reference.LAYOUT.size, 3)), rng.uniform(0.0, 20.0)
        stacked = model.rhs_stack(t, states)
        for i in range(3):
            np.testing.assert_allclose(model.rhs_one(t, states[:, i]), stacked[:, i], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("overrides, omega", [
    (["plant.amplitude=3", "plant.omega=2", "plant.phase=0.5"], 2.0),
    (["plant.x0[1]=0.5", "plant.x0[2]=0.2"], 1.0),
    (["plant.amplitude=2", "plant.omega=3", "plant.x0[1]=2", "plant.x0[2]=-1"], 3.0),
])
def test_other_disturbances_and_initial_states_through_the_plant_parameters(build_dir, fmus, overrides, omega):
    result, summary = run(NAME, build_dir, stop_time=12.0, overrides=parse_overrides(overrides))
    assert result.vector("plant.f_omega")[0, 0] == omega
    e = errors(result)
    last = last_fifth(result)
    # measured (12 s runs): omega 6.3e-11..1.9e-8, xi0 1.2e-8..1.4e-7, f 3.7e-7..1.6e-6, x 1.4e-7..4.6e-7
    assert np.max(np.abs(e["omega"][last])) < 1e-6
    assert np.max(np.abs(e["xi0"][last])) < 1e-5
    assert np.max(np.abs(e["f"][last])) < 1e-4
    assert np.max(e["x_relative"][last]) < 1e-5
    assert np.max(np.abs(e["x_tilde0"][result.index_at(0.1):])) < 1e-6
    np.testing.assert_array_equal(result.vector("observer.identified")[-1], [SETTLED] * 4)


def test_measurement_noise_degrades_gracefully(build_dir, fmus):
    """Noise std 1e-5 (|y| ~ 7): every step returns OK, nothing is NaN, errors stay bounded."""
    result, _ = run(NAME, build_dir, overrides=parse_overrides(["plant.noise_std=1e-5"]))
    assert np.all(np.isfinite(result.values))
    e = errors(result)
    last = last_fifth(result)
    # xi(0) is seen only in the plant's transient: stages 2-4 do not settle, stop at t_identify = 10 s
    # (stage 4: 10 s after its start) and keep the moving average of their estimates
    np.testing.assert_array_equal(result.vector("observer.identified")[-1], [SETTLED, TIMED_OUT, TIMED_OUT,
                                                                               TIMED_OUT])
    assert np.max(np.abs(e["omega"][last])) < 1e-3             # 4.3e-5 (seeds 0-2: 5e-6 .. 4e-5)
    assert np.max(np.abs(e["xi0"][last])) < 5e-2               # 9.3e-3 (9e-4 .. 1.2e-2)
    assert np.max(np.abs(e["f"][last])) < 0.5                  # 5.7e-2 (3e-2 .. 8e-2)
    assert np.max(e["x_relative"][last]) < 0.1                 # 1.2e-2 (6e-3 .. 1.2e-2)
    assert np.max(np.abs(e["x_tilde0"][result.index_at(0.1):])) < 1e-6   # stage 1 sees no noise here (L~ = 0)


def test_holding_y_costs_accuracy(build_dir, fmus):
    """The scenario table: held y lags by h/2 (omega error 2e-3 instead of 3e-9 at 12 s)."""
    result, _ = run(NAME, build_dir, stop_time=12.0, coupling="hold")
    e = errors(result)
    assert np.max(np.abs(e["omega"][last_fifth(result)])) > 1e-4


def test_a_bad_parameter_is_reported_naming_it(build_dir, fmus):
    with pytest.raises(SimulationError, match=r"r: rank\(C A\^0 B\) = 0 != rank B = 1"):
        run(NAME, build_dir, stop_time=0.01, overrides=parse_overrides(["observer.r=1"]))
    with pytest.raises(SimulationError, match=r"L: not Hurwitz"):
        run(NAME, build_dir, stop_time=0.01, overrides=parse_overrides(["observer.L[1]=-0.4"]))


def test_summary_reports_the_acceptance_numbers(default_run):
    result, _ = default_run
    summary = summarize(result)
    text = str(summary)
    assert "identified at 0.056 s" in text and "reference" in text
    assert summary.metrics["omega_error_last20"] < 1e-4
