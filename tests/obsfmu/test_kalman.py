"""The luenberger observer's Kalman design (Q, R): the steady-state LQE gain against python-control's lqe."""

import numpy as np
import pytest

import obsfmu


def built_gain(definition, name: str):
    """The gain the build designed: the FMU's parameter, or (a tunable Riccati design) where its Newton iteration
    starts at initialisation."""
    given = [p.value for p in definition.parameters if p.name == name]
    return np.ravel(given[0] if given else definition.options["initial_gain"])

control = pytest.importorskip("control")

A, B, C = np.array([[0.0, 1.0], [-2.0, -3.0]]), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])
Q, R = np.diag([0.0, 1.0]), np.array([[1e-2]])


def spec(tmp_path, **observer):
    system = obsfmu.System("kalman", stop_time=0.1, step=1e-3)
    system.add("plant", obsfmu.lti(A, B, C))
    system.add("observer", kind="luenberger", plant="plant", **observer)
    system.values["plant.u"] = 0.0
    system.values["observer.u"] = 0.0
    system.connect("plant.y", "observer.y")
    return obsfmu._internals.load_system(system.save(tmp_path / "kalman.toml"))


def test_the_kalman_gain_is_python_controls_lqe(tmp_path):
    definition = spec(tmp_path, Q=Q, R=R).components["observer"].definitions[0]
    N = np.array(built_gain(definition, "N"))
    expected, _, _ = control.lqe(A, np.eye(2), C, Q, R)
    assert np.allclose(N, np.ravel(expected), rtol=1e-10, atol=0), (N, expected)


@pytest.mark.parametrize("observer, message", [
    ({"Q": Q}, r"needs both Q and R"),
    ({"Q": Q, "R": R, "poles": [-5, -6]}, r"none of poles"),
    ({"Q": Q, "R": [[0.0]]}, r"R: a covariance must be positive definite"),
    ({"Q": [[1.0, 2.0], [0.0, 1.0]], "R": R}, r"Q: a covariance must be symmetric"),
])
def test_a_bad_kalman_request_is_named(tmp_path, observer, message):
    with pytest.raises(obsfmu.ParameterError, match=message):
        spec(tmp_path, **observer)


# --- Q and R as the FMU's parameters: the gain designed at initialisation (Newton's method, numpy only) ----------
def test_r_set_at_run_time_gives_python_controls_lqe_gain(tmp_path):
    """The observer FMU carries Q and R and designs N at initialisation: with R set to 1e-4 at run time the
    estimate is that of control.lqe's gain for 1e-4 (one 4-state model, forced_response), not of the built 1e-2."""
    path = spec(tmp_path, Q=Q, R=R).path
    x0 = [1.0, 0.5]
    result = obsfmu.run(path, build_dir=tmp_path / "build", stop_time=1.0,
                        set={"observer.R[1,1]": 1e-4, "plant.x0": x0})

    def estimate(r):
        N, _, _ = control.lqe(A, np.eye(2), C, Q, [[r]])
        loop = control.ss(np.block([[A, np.zeros((2, 2))], [N @ C, A - N @ C]]), np.zeros((4, 1)), np.eye(4), 0)
        return control.initial_response(loop, result.time, x0 + [0.0, 0.0]).states[2:].T

    deviation = np.max(np.abs(result["observer.x_hat"] - estimate(1e-4)))
    assert deviation < 1e-4 * np.max(np.abs(estimate(1e-4)))       # measured 2.4e-7: the y coupling at 1 ms
    assert np.max(np.abs(result["observer.x_hat"] - estimate(1e-2))) > 100 * deviation
    assert result.parameters["observer.R[1,1]"] == 1e-4


@pytest.mark.parametrize("setting, message", [
    ({"observer.R[1,1]": -1.0}, r"R: a covariance must be positive definite"),
    ({"observer.Q[1,2]": 1.0}, r"Q: a covariance must be symmetric"),
])
def test_bad_weights_set_at_run_time_are_an_error_naming_them(tmp_path, setting, message):
    with pytest.raises(obsfmu.SimulationError, match=message):
        obsfmu.run(spec(tmp_path, Q=Q, R=R).path, build_dir=tmp_path / "build", set=setting)
