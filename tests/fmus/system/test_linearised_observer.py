"""Issue 38: a luenberger observer designed from an expression plant's linearisation at a stated operating point
(numerical Jacobians, checked) -- no hand-copied linear model.  Against the analytic Jacobians, against the
example's hand-linearised observer, and off equilibrium against a scipy solution of plant + affine observer."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import obsfmu
from obsfmu.fmus.system.load import parse_system
from obsfmu.observers.checks import ParameterError
from obsfmu.observers.linearise import linearise
from obsfmu.observers.modal import observer_gain

ROOT = Path(__file__).resolve().parents[3]
EXAMPLE = (ROOT / "examples" / "pendulum.toml").read_text()
G_L, FRICTION = 9.81 / 0.5, 0.3


def pendulum_f(t, x, u, p):
    return np.array([x[1], -G_L * np.sin(x[0]) - FRICTION * x[1] + (u[0] if len(u) else 0.0)])


def pendulum_h(t, x, u, p):
    return np.array([x[0]])


def test_the_jacobians_are_the_analytic_ones_and_a_kink_is_refused():
    lin = linearise(pendulum_f, pendulum_h, [0.3, 0.2], [0.5], [])
    np.testing.assert_allclose(lin.A, [[0.0, 1.0], [-G_L * np.cos(0.3), -FRICTION]], rtol=0, atol=1e-8)
    np.testing.assert_allclose(lin.B, [[0.0], [1.0]], atol=1e-9)
    np.testing.assert_allclose(lin.C, [[1.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(lin.f0, pendulum_f(0, [0.3, 0.2], [0.5], []))
    with pytest.raises(ParameterError, match=r"x\[1\] changes with the difference step.*not smooth"):
        linearise(lambda t, x, u, p: np.abs(x), pendulum_h, [0.0, 0.0], [], [])


def test_the_example_observer_designed_from_the_plant_itself_equals_the_hand_linearised_one(tmp_path):
    """examples/pendulum.toml copies the linearisation at rest into an lti component; x_op = [0, 0] on the
    expression plant gives the same observer (its A differs from -19.62 by the differences' 1e-9)."""
    direct = EXAMPLE.replace('plant = "linearised"', 'plant = "plant"\nx_op = [0.0, 0.0]')
    assert direct != EXAMPLE
    spec = parse_system(direct, str(ROOT / "examples" / "direct.toml"))
    assert any("'plant' linearised at x = [0, 0]" in note for note in spec.notes)
    (tmp_path / "hand.toml").write_text(EXAMPLE)
    (tmp_path / "direct.toml").write_text(direct)
    hand = obsfmu.run(tmp_path / "hand.toml", stop_time=2.0, build_dir=tmp_path / "build")
    mine = obsfmu.run(tmp_path / "direct.toml", stop_time=2.0, build_dir=tmp_path / "build")
    for column in ("observer.x_hat[1]", "observer.x_hat[2]"):
        np.testing.assert_allclose(mine[column], hand[column], rtol=0, atol=1e-7)     # measured < 1e-9


OFF_EQUILIBRIUM = """
name = "forced"
connections = ["force.y -> plant.u", "force.y -> observer.u", "plant.y -> observer.y"]
[experiment]
stop_time = 3.0
step = 1e-3
[components.force]
kind = "multisine"
amplitudes = [0.5]
frequencies_hz = [0.3]
offset = 1.0
[components.plant]
kind = "expression"
inputs = 1
parameters = { g = 9.81, l = 0.5, c = 0.3 }
f = ["x[2]", "-g / l * sin(x[1]) - c * x[2] + u[1]"]
h = ["x[1]"]
x0 = [0.4, 0.0]
max_substep = 1e-4
[components.observer]
kind = "luenberger"
plant = "plant"
x_op = [0.3, 0.1]
u_op = [1.0]
poles = [-8, -9]
"""


def test_off_equilibrium_the_affine_observer_is_the_scipy_solution(tmp_path):
    """At x_op = [0.3, 0.1], u_op = 1 (not an equilibrium: f there = [0.1, -3.83]) the observer is
    x_hat' = A x_hat + B u + N (y - C x_hat - e) + c; its FMU run agrees with a scipy solution of plant and that
    observer written here from the analytic Jacobians."""
    (tmp_path / "forced.toml").write_text(OFF_EQUILIBRIUM)
    result = obsfmu.run(tmp_path / "forced.toml", build_dir=tmp_path / "build")
    x_op, u_op = np.array([0.3, 0.1]), np.array([1.0])
    A = np.array([[0.0, 1.0], [-G_L * np.cos(0.3), -FRICTION]])
    B, C = np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])
    N = observer_gain(A, C, np.array([-8.0, -9.0]), "poles")
    c = pendulum_f(0, x_op, u_op, []) - A @ x_op - B @ u_op
    e = pendulum_h(0, x_op, u_op, []) - C @ x_op

    def force(t):
        return 1.0 + 0.5 * np.sin(2 * np.pi * 0.3 * t)

    def rhs(t, z):
        x, x_hat, u = z[:2], z[2:], np.array([force(t)])
        y, y_hat = pendulum_h(t, x, u, []), C @ x_hat + e
        return np.concatenate([pendulum_f(t, x, u, []), A @ x_hat + B @ u + N @ (y - y_hat) + c])
    reference = solve_ivp(rhs, (0.0, 3.0), [0.4, 0.0, 0.0, 0.0], method="DOP853", rtol=1e-11, atol=1e-12,
                          t_eval=result.time, dense_output=False)
    for j in (1, 2):
        deviation = np.max(np.abs(result[f"observer.x_hat[{j}]"] - reference.y[1 + j]))
        assert deviation < 1e-5, (j, deviation)          # the y coupling at 1e-3 s: measured 4.9e-7, 2.1e-6
