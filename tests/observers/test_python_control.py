"""python-control interop: its systems are taken wherever a plant is, and the design functions give
the gains of control.place / control.acker (python-control is an optional test dependency)."""

from __future__ import annotations

import numpy as np
import pytest

from obsfmu.observers.checks import ParameterError
from obsfmu.observers.lti_model import StateSpace
from obsfmu.observers.modal import ackermann, design_observer, design_state_feedback, observer_gain, place
from obsfmu.plants.lti import LTIPlant
from obsfmu.observers.block import Segment

control = pytest.importorskip("control")


def random_system(rng, n, m, p):
    while True:
        A, B, C = rng.standard_normal((n, n)), rng.standard_normal((n, m)), rng.standard_normal((p, n))
        if np.linalg.matrix_rank(control.ctrb(A, B)) == n and np.linalg.matrix_rank(control.obsv(A, C)) == n:
            return A, B, C


@pytest.mark.parametrize("n, m, seed", [(2, 1, 0), (3, 1, 1), (4, 1, 2), (4, 2, 3), (5, 2, 4), (6, 3, 5)])
def test_place_gives_the_gain_of_control_place(n, m, seed):
    rng = np.random.default_rng(seed)
    A, B, _ = random_system(rng, n, m, 1)
    poles = -np.linspace(1.0, 3.0, n)
    ours, theirs = place(A, B, poles), control.place(A, B, poles)
    np.testing.assert_allclose(ours, theirs, rtol=1e-7, atol=1e-9 * np.abs(theirs).max())
    np.testing.assert_allclose(np.sort(np.linalg.eigvals(A - B @ ours).real), np.sort(poles), rtol=1e-8)


@pytest.mark.parametrize("n, seed", [(2, 10), (3, 11), (5, 12)])
def test_ackermann_gives_the_gain_of_control_acker(n, seed):
    rng = np.random.default_rng(seed)
    A, b, _ = random_system(rng, n, 1, 1)
    poles = [-1.0 + 0.5j, -1.0 - 0.5j, -2.0, -2.5, -3.0][:n] if n != 2 else [-1.0, -2.0]
    np.testing.assert_allclose(np.ravel(ackermann(A, b, poles)), np.ravel(control.acker(A, b, poles)), rtol=1e-8)


def test_a_control_statespace_is_taken_for_design():
    system = control.ss([[0, 1], [-2, 3]], [[0], [1]], [[1, 0]], 0)            # paper 002's ship
    N = design_observer(system, t_settle=0.15)
    K = design_state_feedback(system, t_settle=0.3)
    np.testing.assert_allclose(N, [[83.0], [1847.0]], rtol=1e-12)          # the paper's printed gains
    np.testing.assert_allclose(K, [[398.0, 43.0]], rtol=1e-12)
    np.testing.assert_allclose(N, control.place(system.A.T, system.C.T, [-40.0, -40.0 + 1e-7]).T, rtol=1e-5)
    np.testing.assert_allclose(observer_gain(system.A, system.C, [-3.0, -4.0]),
                               control.place(system.A.T, system.C.T, [-3.0, -4.0]).T, rtol=1e-10)


def test_a_continuous_control_system_as_a_plant_follows_forced_response():
    system = control.ss([[0, 1], [-2, -0.4]], [[0], [1]], [[1, 0]], 0)
    T = np.linspace(0.0, 5.0, 501)
    U = np.sin(1.3 * T)
    expected = control.forced_response(system, T, U, X0=[0.3, 0.0]).outputs
    plant = LTIPlant(system, x0=[0.3, 0.0])
    y = [plant.outputs(0.0, {"u": U[:1]})["y"][0]]
    for k in range(len(T) - 1):                       # forced_response: the input linear between the points
        h = T[k + 1] - T[k]
        plant.advance(T[k], h, {"u": Segment.between(U[k:k + 1], U[k + 1:k + 2], h)})
        y.append(plant.outputs(T[k + 1], {"u": U[k + 1:k + 2]})["y"][0])
    np.testing.assert_allclose(y, expected, atol=1e-9)


def test_a_discrete_control_system_as_a_plant_takes_its_samples():
    system = control.ss([[0.9, 0.1], [0.0, 0.8]], [[0.0], [0.5]], [[1, 1]], 0, dt=0.1)
    T = np.arange(0, 41) * 0.1
    U = np.cos(T)
    expected = control.forced_response(system, T, U, X0=[1.0, -1.0]).outputs
    plant = LTIPlant(system, x0=[1.0, -1.0])
    assert StateSpace.of(system).dt == 0.1
    y = [plant.outputs(0.0, {"u": U[:1]})["y"][0]]
    for k in range(0, 40, 2):                         # two samples per communication step
        plant.advance(T[k], 0.2, {"u": Segment.between(U[k:k + 1], U[k + 1:k + 2], 0.1)})
        y.append(plant.outputs(T[k + 2], {"u": U[k + 2:k + 3]})["y"][0])
    np.testing.assert_allclose(y, expected[::2], atol=1e-12)


def test_systems_that_cannot_be_taken_are_refused_by_name():
    with pytest.raises(ParameterError, match="plant.dt: a discrete system needs its sample time"):
        StateSpace.of(control.ss([[0.5]], [[1]], [[1]], 0, dt=True), prefix="plant.")
    with pytest.raises(ParameterError, match="expected a state-space system"):
        StateSpace.of(control.tf([1], [1, 1]))
    with pytest.raises(ParameterError, match=r"expected \(A, B, C, D\), got 2 matrices"):
        StateSpace.of(([[1.0]], [[1.0]]))
