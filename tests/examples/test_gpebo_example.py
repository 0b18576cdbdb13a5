"""Worked example of the gpebo-observer (examples/gpebo_shift3.toml) against an independent reference.

The plant: ``x1(k+1) = x2(k)``, ``x2(k+1) = x3(k) + theta2(k) tanh(y(k))``, ``x3(k+1) = beta(k) u(k)``,
``y = x1``, ``beta(k+3) = g_b beta(k)``, ``theta2(k+3) = g_t theta2(k)`` (3-dimensional generators).
The reference below is written from these equations only (plain numpy, nothing of the project):

* the plant as a plain loop;
* ``g_b, g_t`` by a *batch* method instead of DREM: ``y(k+3) = beta(k) u(k) + theta2(k+1) tanh(y(k+1))``
  written at ``k, k+3, k+6`` gives ``det [[u0, s1, y3], [a u3, b s4, y6], [a^2 u6, b^2 s7, y9]] = 0``
  (``a = g_b``, ``b = g_t``), expanded by hand: linear in ``m = (b, b^2, a, a^2, a b^2, a^2 b)``; ``m`` is
  the null vector of the stacked rows (SVD), ``a = m_4 / m_3``, ``b = m_2 / m_1``;
* ``xi(0)`` by batch least squares on ``y(k) = phi_y(k) xi(0)`` (``k >= 3``), ``phi`` the response of the
  loop to each unit generator state with the measured ``y`` in the nonlinearity, then ``x = phi_x xi(0)``.

The co-simulation runs through the CLI (``python -m obsfmu run --config``), once per session.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from examples_support import ROOT, columns, first_from_which, flag_lag, run_config

EXAMPLE = ROOT / "examples" / "gpebo_shift3.toml"
G_B, G_T = -1.0, 1.0
XI_B0, XI_T0, X0 = [1.0, 0.5, -0.3], [0.5, -0.4, 0.8], [0.3, -0.2, 0.1]
SAMPLES = 60
TOLERANCE = 1e-6          # the file's converged_tolerance


def generator(g: float) -> np.ndarray:
    """``xi(k+1) = G xi(k)`` with ``w = xi_1``: ``w(k+3) = g w(k)``."""
    return np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [g, 0.0, 0.0]])


def u_of(k: int) -> float:
    return math.sin(k) + 0.5 * math.sin(2.3 * k)


def reference_plant(u, g_b=G_B, g_t=G_T):
    """Plain loop: x (K+1, 3) and the stacked generator states xi (K+1, 6)."""
    xb, xt, x = np.array(XI_B0), np.array(XI_T0), np.array(X0)
    xs, xis = [x.copy()], [np.concatenate([xb, xt])]
    for uk in u:
        x = np.array([x[1], x[2] + xt[0] * math.tanh(x[0]), xb[0] * uk])
        xb, xt = generator(g_b) @ xb, generator(g_t) @ xt
        xs.append(x.copy())
        xis.append(np.concatenate([xb, xt]))
    return np.array(xs), np.array(xis)


def reference_gammas(u, y) -> tuple[float, float]:
    """Batch: the null vector of the hand-expanded determinant rows."""
    s = np.tanh(y)
    rows = [[u[k] * s[k + 4] * y[k + 9], -u[k] * s[k + 7] * y[k + 6], -s[k + 1] * u[k + 3] * y[k + 9],
             s[k + 1] * u[k + 6] * y[k + 6], u[k + 3] * s[k + 7] * y[k + 3], -u[k + 6] * s[k + 4] * y[k + 3]]
            for k in range(len(y) - 9)]
    m = np.linalg.svd(np.array(rows))[2][-1]
    return m[3] / m[2], m[1] / m[0]


def reference_state(u, y, g_b, g_t):
    """``xi(0)`` by batch least squares on ``y = phi_y xi(0)`` (k >= 3), then ``x(k) = phi_x(k) xi(0)``."""
    K = len(y)
    Gamma = np.zeros((6, 6))
    Gamma[:3, :3], Gamma[3:, 3:] = generator(g_b), generator(g_t)
    phi = np.zeros((K, 3, 6))            # x(k) = phi(k) xi(0) + (terms of x(0), zero for k >= 3)
    power = np.eye(6)
    for k in range(K - 1):
        xi_rows = power                  # xi(k) = Gamma^k xi(0)
        phi[k + 1, 0] = phi[k, 1]
        phi[k + 1, 1] = phi[k, 2] + math.tanh(y[k]) * xi_rows[3]
        phi[k + 1, 2] = u[k] * xi_rows[0]
        power = Gamma @ power
    xi0 = np.linalg.lstsq(phi[3:, 0], y[3:], rcond=None)[0]
    return phi @ xi0, xi0


def run_example(tmp: Path, build: Path, *sets: str) -> dict[str, np.ndarray]:
    tmp.mkdir(parents=True, exist_ok=True)
    return run_config(EXAMPLE, tmp / "run.csv", "--build-dir", build, *[f"--set={item}" for item in sets])[0]


@pytest.fixture(scope="session")
def build(tmp_path_factory):
    return tmp_path_factory.mktemp("gpebo_example_build")


@pytest.fixture(scope="session")
def cosim(tmp_path_factory, build):
    return run_example(tmp_path_factory.mktemp("gpebo_example"), build)


@pytest.fixture(scope="session")
def reference():
    u = np.array([u_of(k) for k in range(SAMPLES)])
    x, xi = reference_plant(u)
    g_b, g_t = reference_gammas(u, x[:SAMPLES, 0])
    x_batch, xi0 = reference_state(u, x[:SAMPLES, 0], g_b, g_t)
    return {"u": u, "x": x, "xi": xi, "gammas": np.array([g_b, g_t]), "x_batch": x_batch, "xi0": xi0}


def test_plant_agrees_with_the_plain_loop(cosim, reference):
    np.testing.assert_allclose(cosim["source.y"][:SAMPLES], reference["u"], rtol=0, atol=1e-15)
    assert np.max(np.abs(columns(cosim, "plant.x", 3) - reference["x"])) < 1e-13


def test_reference_methods_recover_the_truth(reference):
    np.testing.assert_allclose(reference["gammas"], [G_B, G_T], atol=1e-10)
    np.testing.assert_allclose(reference["xi0"], XI_B0 + XI_T0, atol=1e-9)
    assert np.max(np.abs(reference["x_batch"][3:SAMPLES] - reference["x"][3:SAMPLES])) < 1e-9


def test_observer_converges_to_the_reference(cosim, reference):
    gamma_hat = columns(cosim, "observer.gamma_hat", 2)
    x_error = np.max(np.abs(columns(cosim, "plant.x", 3) - columns(cosim, "observer.x_hat", 3)), axis=1)
    assert np.max(np.abs(gamma_hat[-1] - reference["gammas"])) < 1e-10
    assert np.max(np.abs(columns(cosim, "observer.x_hat", 3)[SAMPLES - 1] - reference["x_batch"][-1])) < 1e-9
    assert x_error[-1] < 1e-11
    # the measured convergence (docs/adaptive-gpebo.md): gamma from sample 15, x from sample 24
    gamma_from = first_from_which(np.max(np.abs(gamma_hat - [G_B, G_T]), axis=1) <= TOLERANCE)
    x_from = first_from_which(x_error <= TOLERANCE)
    assert 10 <= gamma_from <= 20 and 20 <= x_from <= 30, (gamma_from, x_from)


def test_converged_flag_is_never_early(cosim, reference):
    gamma_error = np.max(np.abs(columns(cosim, "observer.gamma_hat", 2) - [G_B, G_T]), axis=1)
    restart = np.rint(cosim["observer.restart_time"]).astype(int)           # eta = xi(restart_time)
    eta_error = np.max(np.abs(columns(cosim, "observer.eta_hat", 6) - reference["xi"][restart]), axis=1)
    lag = flag_lag(cosim["observer.converged"] > 0.5, (gamma_error <= TOLERANCE) & (eta_error <= TOLERANCE))
    assert 0 <= lag <= 3, lag


def test_noise_grows_the_error_and_it_stays_bounded(tmp_path, build):
    """With the noise setting of docs/adaptive-gpebo.md (restart_tol = 1e-4) the error follows the noise."""
    final = []
    for std in (1e-8, 1e-6):
        data = run_example(tmp_path / f"std{std:g}", build, f"sensor.std={std}", "observer.restart_tol=1e-4")
        error = np.max(np.abs(columns(data, "plant.x", 3) - columns(data, "observer.x_hat", 3)), axis=1)
        final.append(float(np.max(error[-10:])))
    assert final[0] < final[1] < 1e-2, final
