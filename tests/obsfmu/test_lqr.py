"""The state-feedback's LQR design (Q, R): the gain against python-control's lqr, the closed loop's cost against
its Lyapunov value, and bad requests named."""

import numpy as np
import pytest
from scipy.linalg import solve_continuous_lyapunov

import obsfmu

from test_kalman import built_gain

control = pytest.importorskip("control")

A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, -2.0, -3.0]])
B = np.array([[0.0, 0.0], [0.0, 1.0], [1.0, 0.0]])
C = np.array([[1.0, 0.0, 0.0]])
Q, R = np.diag([10.0, 1.0, 0.5]), np.diag([0.1, 2.0])


def spec(tmp_path, **controller):
    system = obsfmu.System("lqr", stop_time=0.1, step=1e-3)
    system.add("plant", obsfmu.lti(A, B, C))
    system.add("controller", kind="state-feedback", plant="plant", **controller)
    system.connect("plant.x", "controller.x_hat")
    system.connect("controller.u", "plant.u")
    system.values["controller.r"] = [0.0, 0.0]
    return obsfmu._internals.load_system(system.save(tmp_path / "lqr.toml"))


def gain(spec_):
    definition = spec_.components["controller"].definitions[0]
    return np.array(built_gain(definition, "K")).reshape(2, 3)


def test_the_lqr_gain_is_python_controls_and_minimises_the_cost(tmp_path):
    built = spec(tmp_path, Q=Q, R=R)
    K = gain(built)
    expected, _, _ = control.lqr(A, B, Q, R)
    assert np.allclose(K, expected, rtol=1e-10, atol=1e-12), (K, expected)
    # the cost from x0 is x0' P x0 with P solving the closed loop's Lyapunov equation; any other stabilising
    # gain (here K perturbed) costs more
    def cost(gain_):
        loop = A - B @ gain_
        P = solve_continuous_lyapunov(loop.T, -(Q + gain_.T @ R @ gain_))
        return np.trace(P)
    assert all(cost(K) < cost(K + 0.05 * direction) for direction in np.eye(6).reshape(6, 2, 3))
    assert any("LQR K = " in note for note in built.notes)


@pytest.mark.parametrize("controller, message", [
    ({"Q": Q}, r"an LQR design needs both Q and R"),
    ({"Q": Q, "R": R, "poles": [-5, -6, -7]}, r"none of poles"),
    ({"Q": Q, "R": np.diag([0.1, 0.0])}, r"R: an input weight must be positive definite"),
    ({"Q": -Q, "R": R}, r"Q: a state weight must be positive semidefinite"),
    ({"Q": np.ones((2, 2)), "R": R}, r"Q: expected a 3 x 3 matrix"),
])
def test_a_bad_lqr_request_is_named(tmp_path, controller, message):
    with pytest.raises(obsfmu.ParameterError, match=message):
        spec(tmp_path, **controller)


def test_r_set_at_run_time_gives_python_controls_lqr_loop(tmp_path):
    """The feedback FMU carries Q and R and designs K at initialisation (Newton's method from the built gain):
    with R = diag(1, 0.02) set at run time the loop is control.lqr's for those weights."""
    x0 = [1.0, -0.5, 0.2]
    result = obsfmu.run(spec(tmp_path, Q=Q, R=R).path, build_dir=tmp_path / "build", stop_time=3.0,
                        set={"controller.R[1,1]": 1.0, "controller.R[2,2]": 0.02, "plant.x0": x0})

    def loop(weights):
        K, _, _ = control.lqr(A, B, Q, weights)
        return control.initial_response(control.ss(A - B @ K, B, np.eye(3), 0), result.time, x0).states.T

    expected = loop(np.diag([1.0, 0.02]))
    deviation = np.max(np.abs(result["plant.x"] - expected)) / np.max(np.abs(expected))
    assert deviation < 1e-3                  # measured 5.2e-5: the loop closes over a communication step of 1 ms
    assert np.max(np.abs(loop(R) - expected)) > 10 * deviation * np.max(np.abs(expected))   # the built R: 0.62 off
