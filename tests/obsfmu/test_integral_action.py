"""Issue 38: state feedback with integral action (u = -K x_hat - K_i z, z' = y - r): the gains place the poles
of the augmented loop, the output tracks a constant reference without steady-state error, and the FMUs agree
with a scipy solution of the same closed loop."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import obsfmu

A = np.array([[-2.0, -0.02, 0.0], [1.0, -10.0, 0.0], [0.0, 1.0, 0.0]])     # examples/dcmotor.toml
B, C = np.array([[2.0], [0.0], [0.0]]), np.array([[0.0, 0.0, 1.0]])
POLES = [-4.0, -5.0, -6.0, -7.0]
REFERENCE = 0.05


def system(**controller):
    built = obsfmu.System("servo", stop_time=6.0, step=1e-3)
    built.add("plant", obsfmu.lti(A, B, C))
    built.add("controller", kind="state-feedback", plant="plant", integral=True, **controller)
    built.connect("plant.x", "controller.x_hat")
    built.connect("plant.y", "controller.y")
    built.connect("controller.u", "plant.u")
    built.values["controller.r"] = REFERENCE
    return built


def gains(built, tmp_path):
    """K, K_i as the build designs them (tunable = false: the FMU carries the gains) and the loaded system."""
    built.components["controller"]["tunable"] = False
    spec = obsfmu._internals.load_system(built.save(tmp_path / "servo.toml"))
    values = {p.name: np.array(p.value) for p in spec.components["controller"].definitions[0].parameters}
    return values["K"].reshape(1, 3), values["K_i"].reshape(1, 1), spec


def test_the_gains_place_the_augmented_loop_and_y_tracks_r_as_scipy_says(tmp_path):
    K, K_i, spec = gains(system(poles=POLES), tmp_path)
    augmented = np.block([[A - B @ K, -B @ K_i], [C, np.zeros((1, 1))]])
    np.testing.assert_allclose(np.sort(np.linalg.eigvals(augmented).real), sorted(POLES), rtol=1e-9)
    assert any("eig(A_a - B_a K)" in note for note in spec.notes)
    result = obsfmu.run(system(poles=POLES), build_dir=tmp_path / "build")
    y = result["plant.y"]
    assert abs(y[-1] - REFERENCE) < 1e-6                        # no steady-state error (measured 6.6e-11)

    def rhs(t, s):
        x, z = s[:3], s[3:]
        u = -K @ x - K_i @ z
        return np.concatenate([A @ x + B @ u, C @ x - REFERENCE])
    reference = solve_ivp(rhs, (0.0, 6.0), np.zeros(4), method="DOP853", rtol=1e-11, atol=1e-13, t_eval=result.time)
    assert np.max(np.abs(y - reference.y[2])) < 1e-6             # the x_hat/y coupling at 1e-3 s: 4.3e-8


def test_lqr_designs_the_augmented_loop_and_bad_requests_are_named(tmp_path):
    K, K_i, _ = gains(system(Q=np.diag([1.0, 1.0, 10.0, 100.0]), R=[[0.1]]), tmp_path)
    augmented = np.block([[A - B @ K, -B @ K_i], [C, np.zeros((1, 1))]])
    assert np.max(np.linalg.eigvals(augmented).real) < 0
    with pytest.raises(obsfmu.ParameterError, match=r"controller.poles: expected 4 poles \(the system order\), got 3"):
        gains(system(poles=[-4.0, -5.0, -6.0]), tmp_path)
    two_outputs = obsfmu.System("servo2", stop_time=1.0, step=1e-3)
    two_outputs.add("plant", obsfmu.lti(A, B, np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])))
    two_outputs.add("controller", kind="state-feedback", plant="plant", integral=True, poles=[-4, -5, -6, -7, -8])
    two_outputs.connect("plant.x", "controller.x_hat")
    two_outputs.connect("plant.y", "controller.y")
    two_outputs.connect("controller.u", "plant.u")
    two_outputs.values["controller.r"] = [0.0, 0.0]
    with pytest.raises(obsfmu.ParameterError, match=r"integral: the plant with the integrators of y - r is not "
                                                      r"controllable \(more outputs \(2\) than inputs \(1\)"):
        gains(two_outputs, tmp_path)

