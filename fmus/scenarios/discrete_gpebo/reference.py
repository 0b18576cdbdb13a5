"""Independent plain discrete loops for paper 000's example (plant and observer).

Written from the paper's equations only -- nothing is imported from the project.  Scalar
formulas, explicit 2x2 generators, its own regression normalisation and its own DREM.

Plant (example, n = 2, delta = 0, h_theta = [[1, 0], [0, 0]] so theta2 = 0):

    x1(k+1) = x2(k) + theta1(k) sin x1(k),   x2(k+1) = beta(k) u(k),   y = x1,
    xi_b(k+1) = [[0, 1], [g_b, 0]] xi_b(k),  beta = xi_b[0],
    xi_t(k+1) = [[0, 1], [g_t, 0]] xi_t(k),  theta1 = xi_t[0].

Observer, with a regression derived independently of the code under test: from
y(k+2) = beta(k) u(k) + theta1(k+1) s(k+1) at k, k+2, k+4,

    det [[u0, s1, y2], [g_b u2, g_t s3, y4], [g_b^2 u4, g_t^2 s5, y6]] = 0,

divided here by g_t (the project divides by g_b):

    u0 s3 y6 = [u0 s5 y4, s1 u2 y6, -s1 u4 y4, -u2 s5 y2, u4 s3 y2] . [g_t, g_b/g_t, g_b^2/g_t, g_b g_t, g_b^2],

g_t = sigma_1, g_b = sigma_1 sigma_2.  DREM: the last 5 rows stacked, each divided by its norm,
Delta = det, adj by Cramer's rule, update of Statement 2.  GPEBO filters of Statement 1
(g for beta, Y for theta) restarted when gamma_hat moves by more than 1e-10; the eta DREM
(last 4 rows) uses y(k) = phi_y(k) eta only from 2 samples after a restart.
"""

from __future__ import annotations

import numpy as np

A = np.array([[0.0, 1.0], [0.0, 0.0]])


def generator(g: float) -> np.ndarray:
    return np.array([[0.0, 1.0], [g, 0.0]])


def simulate_plant(g_b, g_t, xi_b0, xi_t0, x0, u):
    """Plain loop over ``len(u)`` samples; returns x (K+1, 2), beta (K+1,), theta1 (K+1,), xi (K+1, 4)."""
    K = len(u)
    x = np.zeros((K + 1, 2))
    xi = np.zeros((K + 1, 4))
    x[0] = x0
    xi[0] = [*xi_b0, *xi_t0]
    for k in range(K):
        b, t = xi[k, 0], xi[k, 2]
        x[k + 1, 0] = x[k, 1] + t * np.sin(x[k, 0])
        x[k + 1, 1] = b * u[k]
        xi[k + 1] = [xi[k, 1], g_b * xi[k, 0], xi[k, 3], g_t * xi[k, 2]]
    return x, xi[:, 0], xi[:, 2], xi


def regression_matrix(u, y, k, g_b, g_t) -> np.ndarray:
    """The 3x3 matrix whose determinant vanishes, at sample ``k`` (uses samples k-6 .. k)."""
    j = k - 6
    s = np.sin
    return np.array([[u[j], s(y[j + 1]), y[j + 2]],
                     [g_b * u[j + 2], g_t * s(y[j + 3]), y[j + 4]],
                     [g_b ** 2 * u[j + 4], g_t ** 2 * s(y[j + 5]), y[j + 6]]])


def regression_row(u, y, k):
    """(zeta, rho) of the g_t-normalised regression at sample k >= 6."""
    j = k - 6
    u0, u2, u4 = u[j], u[j + 2], u[j + 4]
    s1, s3, s5 = np.sin(y[j + 1]), np.sin(y[j + 3]), np.sin(y[j + 5])
    y2, y4, y6 = y[j + 2], y[j + 4], y[j + 6]
    return u0 * s3 * y6, np.array([u0 * s5 * y4, s1 * u2 * y6, -s1 * u4 * y4, -u2 * s5 * y2, u4 * s3 * y2])


def sigma_of(g_b, g_t):
    return np.array([g_t, g_b / g_t, g_b ** 2 / g_t, g_b * g_t, g_b ** 2])


class Drem:
    """DREM with the last ``p`` rows (zeros before), rows normalised, Statement 2 update."""

    def __init__(self, p, gain, theta0):
        self.p, self.gain = p, gain
        self.theta = np.array(theta0, dtype=float)
        self.rows = [np.zeros(p + 1) for _ in range(p - 1)]

    def update(self, z, phi):
        stacked = np.array([np.append(phi, z)] + self.rows[::-1])
        self.rows = self.rows[1:] + [np.append(phi, z)]
        norms = np.linalg.norm(stacked[:, :-1], axis=1)
        norms[norms == 0] = 1.0
        stacked = stacked / norms[:, None]
        M, b = stacked[:, :-1], stacked[:, -1]
        delta = np.linalg.det(M)
        mixed = np.empty(self.p)
        for i in range(self.p):
            Mi = M.copy()
            Mi[:, i] = b
            mixed[i] = np.linalg.det(Mi)
        self.theta = self.theta + delta / (self.gain + delta ** 2) * (mixed - delta * self.theta)
        return delta


def run_observer(u, y, gain=1e-10, gamma0=(-0.5, 0.5), eta0=(0, 0, 0, 0), x_hat0=(0, 0), restart_tol=1e-10):
    """Observer outputs at samples 0 .. K (x_hat, gamma_hat, xi_hat) from u(0..K-1), y(0..K-1)."""
    K = len(u)
    sig = Drem(5, gain, sigma_of(*gamma0))
    gammas = np.array(gamma0, dtype=float)
    eta = Drem(4, gain, eta0)
    Phi_b, Phi_t = np.eye(2), np.eye(2)
    g, Y = np.zeros((2, 2)), np.zeros((2, 2))
    e_hat, age = np.array(x_hat0, dtype=float), 0
    x_hat, gamma_hat, xi_hat = [e_hat.copy()], [gammas.copy()], [np.array(eta0, dtype=float)]
    for k in range(K):
        if k >= 6:
            sig.update(*regression_row(u, y, k))
        new = np.array([sig.theta[0] * sig.theta[1], sig.theta[0]])      # [g_b, g_t]
        if np.max(np.abs(new - gammas)) > restart_tol * max(1.0, np.max(np.abs(new))):
            phi_x = np.hstack([g, Y])
            estimate = phi_x @ eta.theta + e_hat
            xi_now = np.concatenate([Phi_b @ eta.theta[:2], Phi_t @ eta.theta[2:]])
            Phi_b, Phi_t, g, Y, e_hat, age = np.eye(2), np.eye(2), np.zeros((2, 2)), np.zeros((2, 2)), estimate, 0
            eta = Drem(4, gain, xi_now)
            gammas = new
        if age >= 2:
            eta.update(y[k], np.concatenate([g[0], Y[0]]))
        # Statement 1: g(k+1) = A g + [0; 1] h_b Phi_b u,  Y(k+1) = A Y + h_t Phi_t f(y)
        g = A @ g + np.outer([0.0, 1.0], Phi_b[0]) * u[k]
        Y = A @ Y + np.outer([1.0, 0.0], Phi_t[0]) * np.sin(y[k])
        Phi_b, Phi_t = generator(gammas[0]) @ Phi_b, generator(gammas[1]) @ Phi_t
        e_hat, age = A @ e_hat, age + 1
        x_hat.append(np.hstack([g, Y]) @ eta.theta + e_hat)
        gamma_hat.append(np.array([sig.theta[0] * sig.theta[1], sig.theta[0]]))
        xi_hat.append(np.concatenate([Phi_b @ eta.theta[:2], Phi_t @ eta.theta[2:]]))
    return np.array(x_hat), np.array(gamma_hat), np.array(xi_hat)


INPUTS = {
    "sines": lambda t: np.sin(t) + np.sin(2 * t),
    "constant": lambda t: 5.0 + 0.0 * t,
    "exponential": lambda t: np.exp(-0.5 * t),
}
