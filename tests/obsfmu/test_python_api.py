"""The Python API (obsfmu/): docs/python.md's worked example against python-control's forced_response,
lti matrices from constant expressions, python-control systems, results as arrays."""

import numpy as np
import pytest

import obsfmu

control = pytest.importorskip("control")

#: the co-simulation against control.forced_response's exact discretisation (the lti FMU steps exactly
#: for inputs linear between points; the observer is coupled to the plant by a linear input interpolation)
PLANT_TOLERANCE = 1e-9
OBSERVER_TOLERANCE = 1e-5   # measured 2.8e-6 at step 1e-3: the coupling error of the y connection


def motor():
    """docs/python.md's worked example: a DC motor, states current and speed, voltage input."""
    return control.ss([[-64.0, -0.2], [40.0, -2.0]], [[4.0], [0.0]], [[0.0, 1.0]], 0,
                      states=["current", "speed"], inputs=["voltage"], outputs=["speed"], name="motor")


def worked_example():
    motor_ss = motor()
    system = obsfmu.System("motor", stop_time=1.0, step=1e-3)
    system.add("plant", obsfmu.from_statespace(motor_ss, x0=[0.5, 10.0], state_units=["A", "rad/s"]))
    system.add("observer", kind="luenberger", plant="plant", poles=[-20, -25])
    system.values["plant.u"] = 1.0
    system.values["observer.u"] = 1.0
    system.connect("plant.y", "observer.y")
    system.compare("observer.x_hat", "plant.x", tolerance=1e-3)
    return motor_ss, system


@pytest.fixture(scope="module")
def api_folder(tmp_path_factory):
    return tmp_path_factory.mktemp("api")


@pytest.fixture(scope="module")
def example(api_folder):
    motor_ss, system = worked_example()
    result = obsfmu.run(system.save(api_folder / "motor.toml"), build_dir=api_folder / "build")
    return motor_ss, result


def test_build_and_export_give_the_files(example, api_folder):
    fmus = obsfmu.build(api_folder / "motor.toml", api_folder / "build")
    assert sorted(p.name for p in fmus) == ["motor_observer.fmu", "motor_plant.fmu"]
    ssp = obsfmu.export(api_folder / "motor.toml", "ssp", api_folder / "export", build_dir=api_folder / "build")
    assert ssp.suffix == ".ssp" and ssp.stat().st_size > 0


def test_the_worked_example_matches_forced_response(example):
    motor_ss, result = example
    _, y, x = control.forced_response(motor_ss, result.time, np.ones_like(result.time), X0=[0.5, 10.0],
                                      return_x=True)
    assert np.max(np.abs(result["plant.y"] - y)) < PLANT_TOLERANCE * np.max(np.abs(y))
    assert np.max(np.abs(result["plant.x"] - x.T)) < PLANT_TOLERANCE * np.max(np.abs(x))
    # the observer's error e = x - x_hat obeys e' = (A - N C) e (paper000 eq. of the Luenberger observer):
    # with the same input it decays from e(0) = x0 at the designed poles -20, -25, independent of forced_response
    error = result["plant.x"] - result["observer.x_hat"]
    assert np.max(np.abs(error[-1])) < np.exp(-20 * 1.0) * 10 * 50
    assert result.units["plant.x[2]"] == "rad/s"
    assert "observer.x_hat" in result.summary
    assert "none applies" not in result.summary and "paper" not in result.summary   # own-system wording


def test_the_observer_against_its_own_linear_simulation(example):
    """The whole plant + observer as one state-space model, simulated by python-control."""
    motor_ss, result = example
    A, B, C = motor_ss.A, motor_ss.B, motor_ss.C
    N = control.place(A.T, C.T, [-20, -25]).T
    big = control.ss(np.block([[A, np.zeros((2, 2))], [N @ C, A - N @ C]]), np.vstack([B, B]), np.eye(4), 0)
    _, x = control.forced_response(big, result.time, np.ones_like(result.time), X0=[0.5, 10.0, 0, 0])
    assert np.max(np.abs(result["observer.x_hat"] - x[2:].T)) < OBSERVER_TOLERANCE * np.max(np.abs(x))


def test_lti_matrices_take_constant_expressions_never_code(tmp_path):
    system = obsfmu.System("expr")
    system.add("plant", obsfmu.lti(A=[["-16000/250", "2*pi"], [0, -1]], B=[[0], [1]], C=[[1, 0]]))
    system.values["plant.u"] = 0.0
    spec = obsfmu._internals.load_system(system.save(tmp_path / "expr.toml"))
    assert spec.components["plant"].values["A"][0].tolist() == [-64.0, 2 * np.pi]
    bad = obsfmu.System("bad")
    bad.add("plant", obsfmu.lti(A=[["__import__('os')"]], B=[[1]], C=[[1]]))
    bad.values["plant.u"] = 0.0
    with pytest.raises(obsfmu.ParameterError, match=r"components\.plant\.A\[1\]\[1\].*unknown function"):
        bad.save(tmp_path / "bad.toml")


def test_a_statespace_keeps_its_names_and_sample_time():
    discrete = control.ss([[0.5]], [[1.0]], [[2.0]], 0, dt=0.01, states=["level"], inputs=["valve"],
                          outputs=["gauge"], name="tank")
    component = obsfmu.from_statespace(discrete)
    assert component["sample_time"] == 0.01
    assert component["description"] == "tank: x = [level]; u = [valve]; y = [gauge]"
    # issue 38: the names become the component's state/input/output names (FMU descriptions, summaries, figures);
    # python-control's default labels (x[0], ...) are no names
    assert (component["state_names"], component["input_names"], component["output_names"]) == \
        (["level"], ["valve"], ["gauge"])
    unnamed = obsfmu.from_statespace(control.ss([[0.5]], [[1.0]], [[2.0]], 0))
    assert not {"state_names", "input_names", "output_names"} & set(unnamed)
    with pytest.raises(obsfmu.ParameterError, match="statespace: list has no matrix A"):
        obsfmu.from_statespace([1, 2])


def test_results_are_arrays_and_a_frame(example):
    _, result = example
    assert result["plant.x"].shape == (len(result.time), 2)
    assert result.values.shape == (len(result.time), len(result.columns))
    try:
        import pandas  # noqa: F401
    except ImportError:
        with pytest.raises(ImportError, match="needs pandas"):
            result.frame()
    else:
        assert list(result.frame().columns) == result.columns


def test_results_carry_the_names_of_the_statespace(example):
    """Issue 38: the StateSpace's labels name the result's columns (``labels``, ``named_columns``, ``frame(names=
    True)``); columns without a name keep theirs."""
    _, result = example
    assert result.labels["plant.x[1]"] == "current" and result.labels["observer.x_hat[2]"] == "speed"
    assert result.labels["plant.y"] == "speed" and "plant.u" not in result.labels
    named = dict(zip(result.columns, result.named_columns()))
    assert named["plant.x[1]"] == "plant.x.current" and named["observer.x_hat[2]"] == "observer.x_hat.speed"
    assert named["plant.y"] == "plant.y.speed" and named["observer.y_hat"] == "observer.y_hat.speed"
    assert all(named[c] == c for c in result.columns if c not in result.labels)
    assert len(set(named.values())) == len(named)
    try:
        import pandas  # noqa: F401
    except ImportError:
        return
    frame = result.frame(names=True)
    assert np.array_equal(frame["plant.x.current"].to_numpy(), result["plant.x[1]"])


def test_unknown_targets_are_named():
    with pytest.raises(obsfmu.SimulationError, match="unknown scenario 'nope'"):
        obsfmu.scenario("nope")
    with pytest.raises(obsfmu.ParameterError, match="neither a scenario"):
        obsfmu.run("no-such-file.toml")
    assert "ship" in obsfmu.scenarios()


def test_the_csv_names_survive_genfromtxt_as_docs_python_md_says(example, tmp_path):
    _, result = example
    result.to_csv(tmp_path / "run.csv")
    table = np.genfromtxt(tmp_path / "run.csv", delimiter=",", names=True, deletechars="")
    assert np.array_equal(table["plant.x[1]"], result["plant.x[1]"])


def test_the_cli_prints_its_version(capsys):
    from importlib.metadata import version

    from obsfmu.fmus.cli import main as cli
    assert cli.main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"obsfmu {version('obsfmu')}"
