"""Worked example with whole unknown gamma vectors (examples/gpebo_fullgamma.toml) against an independent reference.

The plant: ``x1(k+1) = x2(k) + theta1(k) tanh(y(k))``, ``x2(k+1) = beta(k) u(k)``, ``y = x1``, with
``beta(k+2) = 1.2 beta(k+1) - beta(k)`` and ``theta1(k+2) = theta1(k+1) - 0.96 theta1(k)``
(``Gamma = [[g1, 1], [g2, 0]]``, ``w = xi_1``); the observer estimates all four ``g``.
The reference below is written from these equations only (plain numpy and scipy, nothing of the project):

* the plant as a plain loop;
* ``gamma`` by a *batch* method instead of the determinant regression and DREM: variable projection,
  ``min over gamma`` of the residual of the least-squares fit of ``xi(0)`` in ``y(k) = phi_y(k; gamma) xi(0)``
  (``k >= 2``; ``phi`` the response of the loop to each unit generator state, the measured ``y`` in the
  nonlinearity), from 9 starts (undamped generators of 3 frequencies each), the best residual kept;
* ``xi(0)`` by that least squares at the found ``gamma``, then ``x = phi_x xi(0)``.

The co-simulation runs through the CLI (``python -m obsfmu run --config``), once per session.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy.optimize import least_squares

from examples_support import ROOT, columns, first_from_which, flag_lag, run_config

EXAMPLE = ROOT / "examples" / "gpebo_fullgamma.toml"
GAMMA_B, GAMMA_T = [1.2, -1.0], [1.0, -0.96]
TRUTH = np.array(GAMMA_B + GAMMA_T)
XI_B0, XI_T0, X0 = [1.0, 0.5], [0.5, -0.4], [0.3, -0.2]
SAMPLES = 80
BATCH = 40                # samples the batch reference uses
TOLERANCE = 1e-6          # the file's converged_tolerance


def generator(g) -> np.ndarray:
    """``Gamma = Gamma0 + g e_1^T`` of size 2: ``w(k+2) = g1 w(k+1) + g2 w(k)`` for ``w = xi_1``."""
    return np.array([[g[0], 1.0], [g[1], 0.0]])


def u_of(k: int) -> float:
    return math.sin(k) + 0.5 * math.sin(2.3 * k)


def reference_plant(u):
    """Plain loop: x (K+1, 2) and the stacked generator states xi (K+1, 4)."""
    xb, xt, x = np.array(XI_B0), np.array(XI_T0), np.array(X0)
    xs, xis = [x.copy()], [np.concatenate([xb, xt])]
    for uk in u:
        x = np.array([x[1] + xt[0] * math.tanh(x[0]), xb[0] * uk])
        xb, xt = generator(GAMMA_B) @ xb, generator(GAMMA_T) @ xt
        xs.append(x.copy())
        xis.append(np.concatenate([xb, xt]))
    return np.array(xs), np.array(xis)


def responses(gamma, u, y) -> np.ndarray:
    """``phi(k)`` (K, 2, 4) with ``x(k) = phi(k) xi(0)`` for ``k >= 2`` (the x(0) part has died out)."""
    Gb, Gt = generator(gamma[:2]), generator(gamma[2:])
    phi, power_b, power_t = np.zeros((len(y), 2, 4)), np.eye(2), np.eye(2)
    for k in range(len(y) - 1):
        phi[k + 1, 0] = phi[k, 1]
        phi[k + 1, 0, 2:] += math.tanh(y[k]) * power_t[0]
        phi[k + 1, 1, :2] = u[k] * power_b[0]
        power_b, power_t = Gb @ power_b, Gt @ power_t
    return phi


def fit_xi0(gamma, u, y) -> tuple[np.ndarray, np.ndarray]:
    phi = responses(gamma, u, y)
    xi0 = np.linalg.lstsq(phi[2:, 0], y[2:], rcond=None)[0]
    return xi0, phi


def reference_gammas(u, y) -> np.ndarray:
    """Variable projection from 9 starts; the best residual's gamma."""
    def residual(gamma):
        xi0, phi = fit_xi0(gamma, u, y)
        return phi[2:, 0] @ xi0 - y[2:]
    starts = [[2 * math.cos(w), -1.0] for w in (0.5, 1.5, 2.5)]
    fits = [least_squares(residual, a + b, xtol=1e-15, ftol=1e-15, gtol=1e-15)
            for a, b in itertools.product(starts, starts)]
    return min(fits, key=lambda fit: np.max(np.abs(fit.fun))).x


@pytest.fixture(scope="session")
def cosim(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("gpebo_fullgamma")
    return run_config(EXAMPLE, tmp / "run.csv", "--build-dir", tmp / "build")[0]


@pytest.fixture(scope="session")
def reference():
    u = np.array([u_of(k) for k in range(SAMPLES)])
    x, xi = reference_plant(u)
    gammas = reference_gammas(u[:BATCH], x[:BATCH, 0])
    xi0, _ = fit_xi0(gammas, u, x[:SAMPLES, 0])
    x_batch = responses(gammas, u, x[:SAMPLES, 0]) @ xi0
    return {"u": u, "x": x, "xi": xi, "gammas": gammas, "xi0": xi0, "x_batch": x_batch}


def test_plant_agrees_with_the_plain_loop(cosim, reference):
    np.testing.assert_allclose(cosim["source.y"][:SAMPLES], reference["u"], rtol=0, atol=1e-15)
    assert np.max(np.abs(columns(cosim, "plant.x", 2) - reference["x"])) < 1e-13


def test_reference_batch_recovers_the_truth(reference):
    np.testing.assert_allclose(reference["gammas"], TRUTH, atol=1e-10)
    np.testing.assert_allclose(reference["xi0"], XI_B0 + XI_T0, atol=1e-9)
    assert np.max(np.abs(reference["x_batch"][2:] - reference["x"][2:SAMPLES])) < 1e-9


def test_observer_converges_to_the_reference(cosim, reference):
    gamma_hat = columns(cosim, "observer.gamma_hat", 4)
    x_hat = columns(cosim, "observer.x_hat", 2)
    x_error = np.max(np.abs(columns(cosim, "plant.x", 2) - x_hat), axis=1)
    assert np.max(np.abs(gamma_hat[-1] - reference["gammas"])) < 1e-10
    assert np.max(np.abs(x_hat[SAMPLES - 1] - reference["x_batch"][-1])) < 1e-9
    assert x_error[-1] < 1e-11
    # the measured convergence (docs/adaptive-gpebo.md, "Full gamma"): gamma from sample 38, x from 45
    gamma_from = first_from_which(np.max(np.abs(gamma_hat - TRUTH), axis=1) <= TOLERANCE)
    x_from = first_from_which(x_error <= TOLERANCE)
    assert 33 <= gamma_from <= 43 and 40 <= x_from <= 50, (gamma_from, x_from)


def test_converged_flag_is_never_early(cosim, reference):
    gamma_error = np.max(np.abs(columns(cosim, "observer.gamma_hat", 4) - TRUTH), axis=1)
    restart = np.rint(cosim["observer.restart_time"]).astype(int)           # eta = xi(restart_time)
    eta_error = np.max(np.abs(columns(cosim, "observer.eta_hat", 4) - reference["xi"][restart]), axis=1)
    lag = flag_lag(cosim["observer.converged"] > 0.5, (gamma_error <= TOLERANCE) & (eta_error <= TOLERANCE))
    # the consistency test needs the last p = 29 gamma rows exact after convergence: a lag of about p - 6
    assert 0 <= lag <= 29, lag
