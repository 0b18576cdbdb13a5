"""Observer designs as FMU parameters (issue 38): the Luenberger FMU of a system file designed by t_settle,
real poles or shift carries that design and computes N at initialisation, so --set/--vary change it."""

import numpy as np
import pytest

import obsfmu

control = pytest.importorskip("control")

A, B, C = np.array([[0.0, 1.0], [-2.0, -3.0]]), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])
X0 = [1.0, 0.5]
#: measured 1.7e-7 relative at step 1e-3 (the coupling error of plant.y -> observer.y)
TOLERANCE = 1e-5


def observed(design: dict) -> obsfmu.System:
    system = obsfmu.System("designed", stop_time=0.5, step=1e-3)
    system.add("plant", obsfmu.lti(A, B, C, x0=X0))
    system.add("observer", kind="luenberger", plant="plant", **design)
    system.values["plant.u"] = 1.0
    system.values["observer.u"] = 1.0
    system.connect("plant.y", "observer.y")
    return system


def monolithic(time, poles):
    """Plant and observer as one model, N from control.place (independent of obsfmu's design)."""
    N = control.place(A.T, C.T, poles).T
    big = control.ss(np.block([[A, np.zeros((2, 2))], [N @ C, A - N @ C]]), np.vstack([B, B]), np.eye(4), 0)
    return control.forced_response(big, time, np.ones_like(time), X0=X0 + [0.0, 0.0]).states[2:].T


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("designs")


def test_poles_set_at_run_time_place_the_observer(folder):
    path = observed({"poles": [-5.0, -6.0]}).save(folder / "poles.toml")
    result = obsfmu.run(path, build_dir=folder / "build", set={"observer.poles": [-10.0, -12.0]})
    expected = monolithic(result.time, [-10.0, -12.0])
    assert np.max(np.abs(result["observer.x_hat"] - expected)) < TOLERANCE * np.max(np.abs(expected))
    assert result.parameters["observer.poles[1]"] == -10.0


def test_t_settle_set_at_run_time_equals_the_file_built_with_it(folder):
    varied = obsfmu.run(observed({"t_settle": 0.4}).save(folder / "slow.toml"), build_dir=folder / "build",
                        set={"observer.t_settle": 0.2})
    built = obsfmu.run(observed({"t_settle": 0.2}).save(folder / "fast.toml"), build_dir=folder / "build")
    assert np.max(np.abs(varied["observer.x_hat"] - built["observer.x_hat"])) < 1e-12
    slow = obsfmu.run(folder / "slow.toml", build_dir=folder / "build")
    assert np.max(np.abs(slow["observer.x_hat"] - built["observer.x_hat"])) > 1e-3   # the design mattered


def test_a_bad_design_is_an_error_naming_the_parameter(folder):
    path = observed({"t_settle": 0.4}).save(folder / "slow.toml")
    with pytest.raises(obsfmu.SimulationError, match=r"t_settle: must be > 0, got -1"):
        obsfmu.run(path, build_dir=folder / "build", set={"observer.t_settle": -1.0})


def test_set_parses_a_list_into_elements():
    from obsfmu.fmus.scenarios import parse_overrides
    assert parse_overrides(["observer.poles=[-10, -12,-14]"]) == [
        ("observer", "poles[1]", -10.0), ("observer", "poles[2]", -12.0), ("observer", "poles[3]", -14.0)]


def test_the_cli_sets_a_design_by_a_list_and_refuses_a_bad_one_in_one_line(folder, capsys):
    from obsfmu.fmus.cli import main as cli
    path = observed({"poles": [-5.0, -6.0]}).save(folder / "poles.toml")
    build = str(folder / "build")
    assert cli.main(["run", "--config", str(path), "--build-dir", build, "--set", "observer.poles=[-10,-12]"]) == 0
    assert cli.main(["run", "--config", str(path), "--build-dir", build, "--set", "observer.poles=[-10,0]"]) != 0
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and "poles" in error[0], error


# --- state feedback: the closed loop's design as the FMU's parameter ------------------------------------------

def controlled(design: dict, integral: bool = False) -> obsfmu.System:
    """The plant under state feedback on its true state (u = -K x + r, or with integral action on y - r)."""
    system = obsfmu.System("controlled", stop_time=2.0, step=1e-3)
    system.add("plant", obsfmu.lti(A, B, C, x0=X0))
    system.add("controller", kind="state-feedback", plant="plant", integral=integral, **design)
    system.connect("plant.x", "controller.x_hat")
    system.connect("controller.u", "plant.u")
    if integral:
        system.connect("plant.y", "controller.y")
    system.values["controller.r"] = 1.0
    return system


def closed_loop(time, poles):
    """u = -K x + 1 with K from control.place, as one model (independent of obsfmu's design)."""
    K = control.place(A, B, poles)
    return control.forced_response(control.ss(A - B @ K, B, np.eye(2), 0), time, np.ones_like(time), X0=X0).states.T


def test_feedback_poles_set_at_run_time_place_the_closed_loop(folder):
    path = controlled({"poles": [-3.0, -4.0]}).save(folder / "feedback.toml")
    result = obsfmu.run(path, build_dir=folder / "build", set={"controller.poles": [-6.0, -8.0]})
    expected = closed_loop(result.time, [-6.0, -8.0])
    # measured 1.1e-4 relative, in the first steps: the loop x -> u -> plant closes over a communication step
    # of 1 ms; the built design's poles are 0.29 off (relative)
    deviation = np.max(np.abs(result["plant.x"] - expected)) / np.max(np.abs(expected))
    assert deviation < 1e-3
    assert np.max(np.abs(closed_loop(result.time, [-3.0, -4.0]) - expected)) > 100 * deviation
    assert result.parameters["controller.poles[1]"] == -6.0


def test_integral_feedback_set_at_run_time_equals_the_file_built_with_it(folder):
    fast = {"poles": [-8.0, -9.0, -10.0]}
    varied = obsfmu.run(controlled({"poles": [-3.0, -4.0, -5.0]}, integral=True).save(folder / "servo.toml"),
                        build_dir=folder / "build", set={"controller.poles": fast["poles"]})
    built = obsfmu.run(controlled(fast, integral=True).save(folder / "servo_fast.toml"), build_dir=folder / "build")
    assert np.max(np.abs(varied["plant.x"] - built["plant.x"])) < 1e-12
    slow = obsfmu.run(folder / "servo.toml", build_dir=folder / "build")
    assert np.max(np.abs(slow["plant.x"] - built["plant.x"])) > 1e-3    # the design mattered
    assert abs(built["plant.y"][-1] - 1.0) < 1e-3                         # and y tracks r


def test_a_bad_feedback_design_is_an_error_naming_the_parameter(folder):
    path = controlled({"t_settle": 1.0}).save(folder / "feedback_t.toml")
    with pytest.raises(obsfmu.SimulationError, match=r"t_settle: must be > 0, got -1"):
        obsfmu.run(path, build_dir=folder / "build", set={"controller.t_settle": -1.0})


def test_a_multi_input_design_keeps_its_gain_as_the_parameter_and_says_so(tmp_path):
    system = obsfmu.System("two_inputs", stop_time=0.1, step=1e-3)
    system.add("plant", obsfmu.lti(A, np.eye(2), C))
    system.add("controller", kind="state-feedback", plant="plant", poles=[-3.0, -4.0])
    system.connect("plant.x", "controller.x_hat")
    system.connect("controller.u", "plant.u")
    system.values["controller.r"] = [0.0, 0.0]
    spec = obsfmu._internals.load_system(system.save(tmp_path / "two_inputs.toml"))
    names = [p.name for p in spec.components["controller"].definitions[0].parameters]
    assert names == ["K"]
    assert any("K is the FMU's parameter (this design needs scipy" in note for note in spec.notes)
