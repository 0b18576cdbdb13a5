"""Acceptance of paper 004 through FMUs: the two example scenarios against the independent reference.

Every FMU is built once (session build directory), validated and co-simulated with the
scenario defaults (Gauss-Seidel, linear coupling) and with other true parameters and initial
states set with ``--set``.  The reference is ``fmus/scenarios/state_affine_common/reference.py`` (one ODE, Radau,
rtol 1e-10), written without importing the code under test.
"""

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
from fmpy.validation import validate_fmu

from obsfmu.fmus.cli import main as cli
from obsfmu.fmus.metrics import time_to_stay_below
from obsfmu.fmus.result import Result
from obsfmu.fmus.scenarios import ensure_fmus, get, run
from obsfmu.fmus.scenarios import state_affine_chemostat as chemostat_scenario
from obsfmu.fmus.scenarios import state_affine_common as common
from obsfmu.fmus.scenarios import state_affine_pendulum as pendulum_scenario
from obsfmu.fmus.scenarios.state_affine_common import reference as ref
from obsfmu.fmus.system.load import load_system

TOLERANCE = 1e-4     # acceptance: theta_hat and x_hat to 1e-4


@pytest.fixture(scope="module")
def fmus(build_dir):
    paths = {}
    for name in ("state-affine-pendulum", "state-affine-chemostat"):
        paths.update(ensure_fmus(get(name), build_dir))
    return paths


def test_every_fmu_is_valid(fmus):
    assert len(fmus) == 6
    for path in fmus.values():
        assert validate_fmu(str(path)) == [], path


def _file(scenario) -> dict:
    """The components' field values of the scenario's system file."""
    spec = load_system(scenario.SYSTEM_FILE)
    return {name: component.values for name, component in spec.components.items()}


def test_scenario_defaults_are_the_reference_settings():
    """The reference is computed for the settings of the scenarios' files (no silent drift between the two)."""
    pendulum, settings = _file(pendulum_scenario), ref.PENDULUM
    assert dict(a=pendulum["plant"]["a"], b=pendulum["plant"]["b"]) == settings["true"]
    assert pendulum["plant"]["x0"].tolist() == settings["x0"]
    assert pendulum["observer"]["rates"].tolist() == settings["rates"]
    assert dict(amplitude=pendulum["source"]["amplitude"].tolist(),
                omega=pendulum["source"]["omega"].tolist()) == settings["u"]
    assert (pendulum["observer"]["gamma"], pendulum["observer"]["gamma_x"]) == (settings["gamma"], settings["gamma_x"])
    L = next(p for p in get("state-affine-pendulum").definitions()[2].parameters if p.name == "L")
    np.testing.assert_allclose(L.value, [0.0, settings["omega_L"] ** 2], atol=1e-12)
    chemostat, settings = _file(chemostat_scenario), ref.CHEMOSTAT
    assert chemostat["plant"]["S_in"] == settings["true"]["S_in"] and chemostat["plant"]["x0"].tolist() == settings["x0"]
    assert chemostat["observer"]["rates"].tolist() == settings["rates"]
    assert dict(offset=chemostat["source"]["offset"], amplitude=chemostat["source"]["amplitude"].tolist(),
                omega=chemostat["source"]["omega"].tolist()) == settings["u"]
    assert (chemostat["observer"]["gamma"], chemostat["observer"]["gamma_x"]) == (settings["gamma"],
                                                                                  settings["gamma_x"])


@pytest.mark.parametrize("scenario, example, stop", [(pendulum_scenario, "pendulum", 20.0),
                                                     (chemostat_scenario, "chemostat", 30.0)])
def test_stored_reference_files_are_current(scenario, example, stop):
    """The scenario summaries compare against ``reference.csv``: it must be today's reference."""
    stored, fresh = common.load_reference(scenario.REFERENCE), ref.cached(example, stop, 0.01)
    for key in ("time", "x", "x_hat", "theta_hat", "Delta"):
        np.testing.assert_allclose(stored[key], fresh[key], rtol=1e-9, atol=1e-12, err_msg=key)


def _deviation(result: Result, reference: dict) -> dict[str, float]:
    times = reference["time"]
    rows = [result.index_at(t) for t in times]
    np.testing.assert_allclose(result.time[rows], times, atol=1e-9)
    return {key: float(np.max(np.abs(result.vector(column)[rows] - reference[key])))
            for key, column in (("x", "plant.x"), ("x_hat", "observer.x_hat"), ("theta_hat", "observer.theta_hat"))}


def _accept(result: Result, converged_by: float) -> dict[str, float]:
    """theta_hat and x_hat within 1e-4 of the truth from ``converged_by`` on; returns the measured times."""
    theta_error, x_error = common.errors(result)
    after = result.time >= converged_by
    assert np.abs(theta_error[after]).max() < TOLERANCE
    assert np.abs(x_error[after]).max() < TOLERANCE
    return {"theta": time_to_stay_below(result.time, theta_error, TOLERANCE),
            "x": time_to_stay_below(result.time, x_error, TOLERANCE)}


# ----------------------------------------------------------------------------- pendulum (Statement 2)
def test_pendulum_default_run(fmus, build_dir):
    result, summary = run("state-affine-pendulum", build_dir)
    times = _accept(result, converged_by=3.5)                  # measured: theta 1.343 s, x 2.845 s
    assert times["theta"] < 2.0 and times["x"] < 3.5
    theta_error, x_error = common.errors(result)
    assert np.abs(theta_error[-1]).max() < 1e-5 and np.abs(x_error[-1]).max() < 1e-5   # measured 2.7e-6, 2.9e-6
    deviation = _deviation(result, ref.cached("pendulum", 20.0, 0.01))
    assert deviation["x"] < 1e-5                                # measured 4.2e-6 (u as a chord)
    assert deviation["theta_hat"] < 3e-4                        # measured 8.8e-5 (at the switch)
    assert deviation["x_hat"] < 6e-5                            # measured 2.0e-5 (transient)
    assert summary.metrics["max_deviation_theta_hat"] == pytest.approx(deviation["theta_hat"], rel=0.5)


def test_pendulum_other_plant_through_the_command_line(fmus, build_dir, tmp_path):
    """``obsfmu run state-affine-pendulum --set ...``: other gravity, friction and initial state."""
    csv = tmp_path / "out.csv"
    settings = ["plant.a=4", "plant.b=0.2", "plant.x0[1]=-1", "plant.x0[2]=0.5"]
    argv = ["run", "state-affine-pendulum", "--stop-time", "8", "--csv", str(csv), "--build-dir", str(build_dir)]
    assert cli.main(argv + [item for s in settings for item in ("--set", s)]) == 0
    result = Result.from_csv(csv)
    np.testing.assert_allclose(result.vector("plant.theta")[0], [0.2, 4.0])
    times = _accept(result, converged_by=3.0)                  # measured: theta 0.924 s, x 2.273 s
    reference = ref.cached("pendulum", 8.0, 0.01, true=(("a", 4.0), ("b", 0.2)), x0=(-1.0, 0.5))
    assert np.abs(reference["theta_hat"][-1] - [0.2, 4.0]).max() < 1e-9
    deviation = _deviation(result, reference)
    assert max(deviation.values()) < 1e-4                      # measured 2.1e-5 (plant x), 1.8e-5, 1.2e-5
    print("pendulum --set: times to 1e-4", times, "deviation", deviation)


# ----------------------------------------------------------------------------- chemostat (Statement 1)
def test_chemostat_default_run(fmus, build_dir):
    result, summary = run("state-affine-chemostat", build_dir)
    times = _accept(result, converged_by=5.0)                  # measured: theta 1.622 h, x 3.920 h
    assert times["theta"] < 2.0 and times["x"] < 5.0
    theta_error, x_error = common.errors(result)
    assert np.abs(theta_error[-1]).max() < 1e-5 and np.abs(x_error[-1]).max() < 2e-6   # measured 1.1e-6, 4.7e-7
    deviation = _deviation(result, ref.cached("chemostat", 30.0, 0.01))
    assert deviation["x"] < 1e-6                                # measured 3.3e-7
    assert deviation["theta_hat"] < 5e-5                        # measured 1.2e-5
    assert deviation["x_hat"] < 2e-5                            # measured 5.1e-6


def test_chemostat_other_plant(fmus, build_dir):
    overrides = [("plant", "S_in", 15.0), ("plant", "x0[1]", 1.0), ("plant", "x0[2]", 5.0)]
    result, _ = run("state-affine-chemostat", build_dir, stop_time=12.0, overrides=overrides)
    np.testing.assert_allclose(result.vector("plant.theta")[0], [15.0])
    times = _accept(result, converged_by=5.0)                  # measured: theta 2.292 h, x 3.792 h
    reference = ref.cached("chemostat", 12.0, 0.01, true=(("S_in", 15.0),), x0=(1.0, 5.0))
    deviation = _deviation(result, reference)
    assert max(deviation.values()) < 2e-4                      # measured 7.6e-5 (theta_hat), 1.5e-5 (x_hat)
    print("chemostat --set: times to 1e-4", times, "deviation", deviation)


# ----------------------------------------------------------------------------- errors never crash the host
def _open(path):
    description = read_model_description(str(path))
    slave = FMU2Slave(guid=description.guid, unzipDirectory=extract(str(path)),
                      modelIdentifier=description.coSimulation.modelIdentifier, instanceName="instance")
    slave.instantiate(loggingOn=True)
    return slave, {v.name: v.valueReference for v in description.modelVariables}


def test_observer_fmu_refuses_an_unobservable_pair(fmus, capfd):
    slave, vr = _open(fmus["state_affine_pendulum_observer"])
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.setReal([vr["C[1]"], vr["C[2]"]], [0.0, 1.0])       # y = chi_2: (Lambda, C) not observable
    with pytest.raises(FMICallException, match=r"status 3 \(error\)"):
        slave.exitInitializationMode()
    logged = capfd.readouterr()
    assert "C: the pair (Lambda, C) is not observable" in logged.out + logged.err
    with pytest.raises(FMICallException, match="error"):      # refuses to step (FMI 2.0 error state)
        slave.doStep(0.0, 1e-3)
    slave.reset()                                              # and stays alive: valid defaults again
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    slave.doStep(0.0, 1e-3)
    slave.freeInstance()


def test_observer_fmu_refuses_a_nan_input_and_keeps_its_state(fmus, capfd):
    slave, vr = _open(fmus["state_affine_chemostat_observer"])
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    outputs = [vr["x_hat[1]"], vr["x_hat[2]"], vr["theta_hat[1]"]]
    slave.setReal([vr["y"], vr["u"]], [3.0, 0.25])
    slave.doStep(0.0, 2e-3)
    before = slave.getReal(outputs)
    saved = slave.getFMUstate()
    slave.setReal([vr["y"]], [float("nan")])
    with pytest.raises(FMICallException, match="discard"):
        slave.doStep(2e-3, 2e-3)
    logged = capfd.readouterr()
    assert "input y = nan is not finite" in logged.out + logged.err
    assert slave.getReal(outputs) == before
    slave.setFMUstate(saved)  # FMI 2.0: a failed step is redone from a saved state
    slave.freeFMUstate(saved)
    slave.setReal([vr["y"]], [3.0])
    slave.doStep(2e-3, 2e-3)
    assert np.all(np.isfinite(slave.getReal(outputs)))
    slave.terminate()
    slave.freeInstance()
