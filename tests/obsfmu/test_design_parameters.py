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

def controlled(design: dict, integral: bool = False, name: str = "controlled", plant=None, r=1.0) -> obsfmu.System:
    """The plant (``plant``: an lti component, default A, B, C from X0) under state feedback on its true state
    (u = -K x + r, or with integral action on y - r)."""
    system = obsfmu.System(name, stop_time=2.0, step=1e-3)
    system.add("plant", plant or obsfmu.lti(A, B, C, x0=X0))
    system.add("controller", kind="state-feedback", plant="plant", integral=integral, **design)
    system.connect("plant.x", "controller.x_hat")
    system.connect("controller.u", "plant.u")
    if integral:
        system.connect("plant.y", "controller.y")
    system.values["controller.r"] = r
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


# --- several outputs / inputs: numpy's robust placement in the FMU -----------------------------------------------
A3 = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-6.0, -11.0, -6.0]])
B3 = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
C3 = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
X3 = [1.0, -0.5, 0.2]


def test_two_outputs_poles_set_at_run_time_place_the_observer_as_control_place(folder):
    system = obsfmu.System("two_outputs", stop_time=1.0, step=1e-3)
    system.add("plant", obsfmu.lti(A3, B3, C3, x0=X3))
    system.add("observer", kind="luenberger", plant="plant", poles=[-5.0, -6.0, -7.0])
    system.values["plant.u"] = [1.0, 0.0]
    system.values["observer.u"] = [1.0, 0.0]
    system.connect("plant.y", "observer.y")
    result = obsfmu.run(system.save(folder / "two_outputs.toml"), build_dir=folder / "build",
                        set={"observer.poles": [-8.0, -9.0, -10.0]})
    N = control.place(A3.T, C3.T, [-8.0, -9.0, -10.0]).T
    big = control.ss(np.block([[A3, np.zeros((3, 3))], [N @ C3, A3 - N @ C3]]), np.vstack([B3, B3]), np.eye(6), 0)
    u = np.vstack([np.ones_like(result.time), np.zeros_like(result.time)])
    expected = control.forced_response(big, result.time, u, X0=X3 + [0.0] * 3).states[3:].T
    # measured 1.5e-7 relative: the plant.y -> observer.y coupling at 1 ms (N equals control.place's to 5e-15)
    assert np.max(np.abs(result["observer.x_hat"] - expected)) < TOLERANCE * np.max(np.abs(expected))


def test_two_inputs_feedback_set_at_run_time_places_the_loop_as_control_place(folder):
    system = controlled({"poles": [-2.0, -3.0, -4.0]}, name="two_inputs", plant=obsfmu.lti(A3, B3, C3, x0=X3),
                        r=[0.0, 0.0])
    result = obsfmu.run(system.save(folder / "two_inputs.toml"), build_dir=folder / "build",
                        set={"controller.poles": [-5.0, -6.0, -7.0]})
    K = control.place(A3, B3, [-5.0, -6.0, -7.0])
    expected = control.initial_response(control.ss(A3 - B3 @ K, B3, np.eye(3), 0), result.time, X3).states.T
    # the loop closes over a communication step (as the single-input test): measured 8.4e-5 relative; the built
    # design's loop is 0.57 off
    deviation = np.max(np.abs(result["plant.x"] - expected)) / np.max(np.abs(expected))
    assert deviation < 1e-3
    K_built = control.place(A3, B3, [-2.0, -3.0, -4.0])
    built = control.initial_response(control.ss(A3 - B3 @ K_built, B3, np.eye(3), 0), result.time, X3).states.T
    assert np.max(np.abs(built - expected)) > 10 * deviation * np.max(np.abs(expected))


def test_complex_poles_with_several_inputs_keep_their_gain_as_the_parameter_and_say_so(tmp_path):
    oscillating = np.array([[0.0, 1.0, 0.0], [-4.0, 0.0, 0.0], [0.0, 0.0, -1.0]])     # eigenvalues +-2j, -1
    for design in ({"shift": 2.0}, {"t_settle": 2.0, "form": "butterworth"}):
        system = controlled(design, name="scipy_designs", plant=obsfmu.lti(oscillating, B3, C3), r=[0.0, 0.0])
        spec = obsfmu._internals.load_system(system.save(tmp_path / "scipy_designs.toml"))
        assert [p.name for p in spec.components["controller"].definitions[0].parameters] == ["K"]
        assert any("K is the FMU's parameter (complex poles with several inputs need scipy" in note
                   for note in spec.notes), spec.notes


def test_a_butterworth_t_settle_set_at_run_time_equals_the_file_built_with_it(folder):
    """The Butterworth form's settling time at radius 1 (scipy's step response) travels with the FMU; its complex
    poles are placed in real arithmetic at initialisation."""
    varied = obsfmu.run(observed({"t_settle": 0.4, "form": "butterworth"}).save(folder / "butter_slow.toml"),
                        build_dir=folder / "build", set={"observer.t_settle": 0.2})
    built = obsfmu.run(observed({"t_settle": 0.2, "form": "butterworth"}).save(folder / "butter_fast.toml"),
                       build_dir=folder / "build")
    assert np.max(np.abs(varied["observer.x_hat"] - built["observer.x_hat"])) < 1e-12
    from obsfmu.observers.standard_forms import standard_poles
    expected = monolithic(built.time, standard_poles(2, 0.2, "butterworth"))
    # measured 1.8e-7 relative: the plant.y -> observer.y coupling at 1 ms
    assert np.max(np.abs(built["observer.x_hat"] - expected)) < TOLERANCE * np.max(np.abs(expected))
