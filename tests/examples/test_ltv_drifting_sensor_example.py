"""examples/ltv_drifting_sensor.toml (paper 001's class with ``C(t)`` and three nonlinearities ``f_i(y, t)``)
through the CLI against an independent monolithic scipy solution.

The reference below is written for this test from the physical equations (``M q'' + c q' + k_s q + a_2 q^2
+ a_3 q^3 = u``, ``y = s(t) q``) and paper 001's filters (2)-(6) with one ``rho_i`` per nonlinearity,
regression (7) with ``C(t)`` and least squares in its information form (``P' = gamma Psi^T Psi - beta P``,
``q' = gamma Psi^T z - beta q``, ``Theta_hat = P^-1 q``); it imports nothing of observers/, plants/ or
fmus/.  One ODE of 94 states, DOP853 at rtol 1e-10.
"""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from examples_support import ROOT, columns, run_config

EXAMPLE = ROOT / "examples" / "ltv_drifting_sensor.toml"
STOP = 18.0
MASS, DAMPING, STIFFNESS, QUADRATIC, CUBIC = 1.0, 0.6, 4.0, 0.8, 0.5
Q0, V0 = 0.5, 0.0
GAMMA, BETA, F0 = 1000.0, 0.5, 0.1
TOLERANCE = 1e-3                                      # the file's converged_tolerance
#: Theta = [-x(0); m_1; m_2; m_3], m_i the columns of the gains of q, q^2, q^3 (x = [q; q' + c q / M])
THETA = np.array([-Q0, -(V0 + DAMPING / MASS * Q0), -DAMPING / MASS, -STIFFNESS / MASS, 0.0, -QUADRATIC / MASS,
                  0.0, -CUBIC / MASS])


def force(t):
    return 2.0 * math.sin(2 * math.pi * 0.1 * t) + math.sin(2 * math.pi * 0.37 * t) + math.sin(2 * math.pi * 0.23 * t)


def gain(t):
    """The sensor's known gain s(t): y = s(t) q."""
    return 1.0 + 0.2 * math.sin(0.3 * t)


def reference(times):
    """Plant (physical q, v) + observer in canonical coordinates: Theta_hat, x, x_hat at ``times``."""
    A0 = np.array([[0.0, 1.0], [-9.0, 0.0]])          # A - L(t) C^T(t) with L(t) = [0; 9 / s(t)]
    b = np.array([0.0, 1.0 / MASS])

    def unpack(z):
        q, v, xi, Phi, zb = z[0], z[1], z[2:4], z[4:8].reshape(2, 2), z[8:10]
        rho, P, qv = z[10:22].reshape(3, 2, 2), z[22:86].reshape(8, 8), z[86:94]
        return q, v, xi, Phi, zb, rho, P, qv

    def rhs(t, z):
        q, v, xi, Phi, zb, rho, P, qv = unpack(z)
        u, s = force(t), gain(t)
        y = s * q
        C = np.array([s, 0.0])
        Psi = np.concatenate([-C @ Phi] + [C @ r for r in rho])     # C^T(t) [-Phi, rho_1, rho_2, rho_3]
        residual = y - C @ (xi + zb)                                 # z of (7), the known b u moved left
        nonlinear = [q, q ** 2, q ** 3]                              # f_i(y, t) = (y / s(t))^i
        return np.concatenate([
            [v, (u - DAMPING * v - STIFFNESS * q - QUADRATIC * q ** 2 - CUBIC * q ** 3) / MASS],
            A0 @ xi + np.array([0.0, 9.0 / s]) * y, (A0 @ Phi).ravel(), A0 @ zb + b * u,
            np.concatenate([(A0 @ r + np.eye(2) * f).ravel() for r, f in zip(rho, nonlinear)]),
            (GAMMA * np.outer(Psi, Psi) - BETA * P).ravel(), GAMMA * Psi * residual - BETA * qv])

    start = np.zeros(94)
    start[0], start[1] = Q0, V0
    start[4:8] = np.eye(2).ravel()
    start[22:86] = (F0 * np.eye(8)).ravel()                          # P(0) = F(0)^-1 = f0 I; q(0) = 0
    solution = solve_ivp(rhs, (0.0, times[-1]), start, method="DOP853", rtol=1e-10, atol=1e-12, t_eval=times)
    assert solution.success, solution.message
    theta_hat, x, x_hat = [], [], []
    for z in solution.y.T:
        q, v, xi, Phi, zb, rho, P, qv = unpack(z)
        estimate = np.linalg.solve(P, qv)
        theta_hat.append(estimate)
        x.append([q, v + DAMPING / MASS * q])
        x_hat.append(xi + zb + np.hstack([-Phi, *rho]) @ estimate)
    return np.array(theta_hat), np.array(x), np.array(x_hat)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    tmp_path = tmp_path_factory.mktemp("ltv_drifting")
    return run_config(EXAMPLE, tmp_path / "run.csv", "--stop-time", STOP, "--build-dir", tmp_path / "fmus",
                      cwd=tmp_path)


def test_the_cosimulation_agrees_with_the_scipy_reference(run):
    data, summary = run
    theta_ref, x_ref, x_hat_ref = reference(data["time"])
    assert np.abs(columns(data, "plant.x", 2) - x_ref).max() < 1e-7
    assert np.abs(columns(data, "observer.theta_hat", 8) - theta_ref).max() < 1e-6
    assert np.abs(columns(data, "observer.x_hat", 2) - x_hat_ref).max() < 1e-6
    true = columns(data, "plant.theta", 12)[-1]
    np.testing.assert_allclose(np.concatenate([true[:2], true[6:]]), THETA, atol=1e-15)
    np.testing.assert_allclose(true[2:6], [0.0, 0.0, 0.0, 1.0 / MASS])      # k = 0 and b, known
    assert "observer.m_hat[6] vs plant.theta[12]: final |error|" in summary


def test_all_eight_unknowns_converge_and_the_converged_flag_is_never_early(run):
    data, _ = run
    t = data["time"]
    error = np.linalg.norm(columns(data, "observer.theta_hat", 8) - THETA, axis=1)
    flagged = data["observer.converged"] == 1
    first = t[np.argmax(flagged)]
    true_time = t[np.nonzero(error > TOLERANCE)[0][-1] + 1]
    assert flagged.any() and np.all(error[flagged] <= TOLERANCE) and np.all(flagged[t >= first])
    assert 8.0 < true_time < first < STOP
    assert error[-1] < 1e-4
    x_error = np.abs(columns(data, "observer.x_hat", 2) - columns(data, "plant.x", 2))
    assert x_error[t >= true_time].max() < 1e-3
