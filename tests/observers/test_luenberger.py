"""Luenberger observer, LTI plant and the exact step integrator, against independent solutions."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from obsfmu.observers.block import Segment
from obsfmu.observers.checks import ParameterError
from obsfmu.observers.feedback import StateFeedback
from obsfmu.observers.integrators import LinearPropagator, rk4_step
from obsfmu.observers.luenberger import LuenbergerObserver
from obsfmu.observers.modal import observer_gain
from obsfmu.plants.lti import LTIPlant


def test_linear_propagator_is_exact_for_a_linear_input():
    rng = np.random.default_rng(0)
    A = rng.standard_normal((3, 3)) - 2 * np.eye(3)
    B = rng.standard_normal((3, 2))
    x0, u0, du, h = rng.standard_normal(3), rng.standard_normal(2), rng.standard_normal(2), 0.37
    reference = solve_ivp(lambda t, x: A @ x + B @ (u0 + t * du), (0, h), x0, rtol=1e-13, atol=1e-14).y[:, -1]
    np.testing.assert_allclose(LinearPropagator(A, B).step(x0, h, u0, du), reference, rtol=1e-10, atol=1e-12)


def test_rk4_converges_with_fourth_order():
    f = lambda t, x: np.array([-x[0] * np.cos(t)])  # noqa: E731  exact: x0 exp(-sin t)
    errors = [abs(rk4_step(f, 0.0, np.array([1.0]), 2.0, n)[0] - np.exp(-np.sin(2.0))) for n in (10, 20)]
    assert errors[0] / errors[1] == pytest.approx(16, rel=0.1)


def test_observer_error_decays_as_its_poles_say():
    """e(t) = x - x_hat = expm((A - N C) t) e(0) for any input, MIMO."""
    rng = np.random.default_rng(5)
    A = rng.standard_normal((4, 4))
    B = rng.standard_normal((4, 2))
    C = rng.standard_normal((2, 4))
    N = observer_gain(A, C, [-2, -2, -3, -4])
    plant = LTIPlant(A, B, C, x0=rng.standard_normal(4))
    observer = LuenbergerObserver(A, B, C, N, x_hat0=np.zeros(4))
    e0 = plant.x - observer.x_hat
    h, t = 0.05, 0.0
    for k in range(120):
        u = Segment(np.array([np.sin(t), 1.0]), np.array([np.cos(t), 0.0]))
        y = Segment.hold(plant.outputs(t, {"u": u.start})["y"])
        y_end_plant = LTIPlant(A, B, C, x0=plant.x)
        y_end_plant.advance(t, h, {"u": u})
        y = Segment.between(y.start, y_end_plant.outputs(t + h, {})["y"], h)
        plant.advance(t, h, {"u": u})
        observer.advance(t, h, {"u": u, "y": y})
        t += h
    expected = expm((A - N @ C) * t) @ e0
    # y is interpolated linearly over each step, so e(t) is exact up to O(h^2) local terms
    np.testing.assert_allclose(plant.x - observer.x_hat, expected, atol=2e-4 * np.abs(e0).max())
    assert np.abs(expected).max() < 1e-3 * np.abs(e0).max()


def test_observer_with_exact_measurement_is_exact():
    """With y known exactly over the step (held for an output that is constant), e = expm(H t) e0 exactly."""
    A = np.array([[0.0, 1.0], [-2.0, 3.0]])
    C = np.array([[1.0, 0.0]])
    N = observer_gain(A, C, [-40, -40])
    observer = LuenbergerObserver(A, np.zeros((2, 1)), C, N, x_hat0=[1.0, -1.0])
    # plant at rest at the origin: y = 0 exactly; the estimate is the error with a minus sign
    for k in range(10):
        observer.advance(0.01 * k, 0.01, {"u": Segment.hold([0.0]), "y": Segment.hold([0.0])})
    np.testing.assert_allclose(observer.x_hat, expm((A - N @ C) * 0.1) @ [1.0, -1.0], atol=1e-14)


def test_state_feedback_output():
    block = StateFeedback([[398.0, 43.0]])
    assert block.outputs(0.0, {"x_hat": np.array([1.0, 2.0]), "r": np.array([5.0])})["u"] == pytest.approx([-479.0])


@pytest.mark.parametrize("kwargs, message", [
    (dict(N=[[1.0], [1.0]]), "N: not Hurwitz"),
    (dict(N=[[1.0, 2.0]]), "N: expected 2 rows"),
    (dict(N=[[83.0], [1847.0]], x_hat0=[0.0]), "x_hat0: expected 2 entries"),
    (dict(N=None), "N: the observer gain is required"),
])
def test_observer_refuses_bad_parameters(kwargs, message):
    with pytest.raises(ParameterError, match=message):
        LuenbergerObserver([[0, 1], [-2, 3]], [[0], [1]], [[1, 0]], **kwargs)
