"""The luenberger observer's Kalman design (Q, R): the steady-state LQE gain against python-control's lqe."""

import numpy as np
import pytest

import obsfmu

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
    N = np.array(next(p.value for p in definition.parameters if p.name == "N"))
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
