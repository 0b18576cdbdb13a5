"""A luenberger observer of a sampled lti plant: the predictor x_hat[k+1] = A x_hat + B u + N (y - C x_hat - D u),
with N given or the steady-state discrete Kalman gain of Q and R (against python-control's dlqe), run through
the FMUs and checked against an independent numpy loop of plant and predictor."""

import numpy as np
import pytest

import obsfmu

from test_kalman import built_gain

control = pytest.importorskip("control")

T = 0.1
A = np.array([[1.0, 0.1], [-0.2, 0.9]])
B, C = np.array([[0.0], [0.1]]), np.array([[1.0, 0.0]])
Q, R = np.diag([1e-3, 1e-2]), np.array([[1e-2]])


def system(**observer):
    built = obsfmu.System("sampled", stop_time=3.0, step=0.05)      # two communication steps per sample
    built.add("plant", obsfmu.lti(A, B, C, x0=[1.0, -0.5], sample_time=T))
    built.add("observer", kind="luenberger", plant="plant", **observer)
    built.values["plant.u"] = 0.5
    built.values["observer.u"] = 0.5
    built.connect("plant.y", "observer.y")
    built.compare("observer.x_hat", "plant.x", tolerance=1e-6)
    return built


def gain(built, tmp_path):
    spec = obsfmu._internals.load_system(built.save(tmp_path / "sampled.toml"))
    definition = spec.components["observer"].definitions[0]
    return np.array(built_gain(definition, "N")).reshape(2, 1)


def test_the_discrete_kalman_gain_is_python_controls_dlqe(tmp_path):
    # python-control's estimator is the same predictor, x_e[n+1] = A x_e + B u + L (y - C x_e - D u)
    L, _, _ = control.dlqe(A, np.eye(2), C, Q, R)
    N = gain(system(Q=Q, R=R), tmp_path)
    assert np.allclose(N, L, rtol=1e-10, atol=1e-14), (N, L)
    assert np.max(np.abs(np.linalg.eigvals(A - N @ C))) < 1


def test_the_sampled_observer_through_its_fmu_is_the_predictor_recursion(tmp_path):
    N = gain(system(Q=Q, R=R), tmp_path)
    result = obsfmu.run(system(Q=Q, R=R), build_dir=tmp_path / "build")
    x, x_hat = np.array([1.0, -0.5]), np.zeros(2)           # the independent loop, sample by sample
    expected = {}
    for k in range(31):
        expected[round(k * T, 9)] = x_hat.copy()
        y = C @ x
        x, x_hat = A @ x + B[:, 0] * 0.5, A @ x_hat + B[:, 0] * 0.5 + N @ (y - C @ x_hat)
    rows = [i for i, t in enumerate(result.time) if round(t, 9) in expected]
    assert len(rows) == 31
    for i in rows:
        np.testing.assert_allclose([result["observer.x_hat[1]"][i], result["observer.x_hat[2]"][i]],
                                   expected[round(result.time[i], 9)], rtol=0, atol=1e-12)
    assert abs(result["observer.x_hat[1]"][-1] - result["plant.x[1]"][-1]) < 1e-3


@pytest.mark.parametrize("observer, message", [
    ({"poles": [0.5, 0.6]}, r"is discrete \(sample_time\); give N .* or Q and R"),
    ({"N": [[2.5], [0.0]]}, r"N: eig\(A - N C\) = \[.*\] not all inside the unit circle"),
    ({}, r"give N or Q and R"),
])
def test_a_sampled_observer_refuses_continuous_designs_and_unstable_gains(tmp_path, observer, message):
    with pytest.raises(obsfmu.ParameterError, match=message):
        gain(system(**observer), tmp_path)


def test_r_set_at_run_time_gives_the_dlqe_predictor(tmp_path):
    """The sampled observer's FMU designs its Kalman gain at initialisation from the Q and R it carries: with R
    set to 1 the estimate is the predictor recursion with control.dlqe's gain for R = 1, to 1e-12."""
    L, _, _ = control.dlqe(A, np.eye(2), C, Q, [[1.0]])
    result = obsfmu.run(system(Q=Q, R=R).save(tmp_path / "sampled.toml"), build_dir=tmp_path / "build",
                        set={"observer.R[1,1]": 1.0})
    x, x_hat = np.array([1.0, -0.5]), np.zeros(2)
    for _ in range(30):
        y = C @ x
        x, x_hat = A @ x + B[:, 0] * 0.5, A @ x_hat + B[:, 0] * 0.5 + L @ (y - C @ x_hat)
    np.testing.assert_allclose(result["observer.x_hat"][-1], x_hat, rtol=0, atol=1e-12)
    assert np.max(np.abs(L - gain(system(Q=Q, R=R), tmp_path))) > 1e-3          # R mattered
