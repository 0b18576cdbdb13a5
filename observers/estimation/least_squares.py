r"""Least squares with forgetting factor and a bound on the gain (paper 001).

Paper 001 (Kozachek, Bobtsov, Nikolaev 2023), the estimator following its
eq. (10), for the regression (7) ``z = Psi Theta``:

.. math::
    \dot{\hat\Theta} &= \gamma F \Psi^T (z - \Psi \hat\Theta), \\
    \dot F &= -\gamma F \Psi^T \Psi F + \beta F \quad\text{if } \lambda_{\max}(F) \le M,
    \qquad \dot F = 0 \text{ otherwise}, \qquad F(0) = I / f_0 .

With the paper's gains (``gamma = 1000``, ``f0 = 0.1``) the rate
``gamma Psi F Psi^T`` is about 1e4 1/s at ``t = 0``: explicit schemes need
steps well below 1e-4 s.  In the information form ``P = F^{-1}`` the law is
linear and non-stiff,

.. math:: \dot P = \gamma \Psi^T \Psi - \beta P, \qquad
          q = P \hat\Theta, \quad \dot q = \gamma \Psi^T z - \beta q,

so a step with ``z``, ``Psi`` held is solved exactly:

.. math::
    P^+ = e^{-\beta dt} P + w\,\Psi^T\Psi, \qquad
    \hat\Theta^+ = \hat\Theta + w\,(P^+)^{-1} \Psi^T (z - \Psi\hat\Theta), \qquad
    w = \gamma\,dt\,\varphi_1(\beta\,dt)

(the second line is ``(P^+)^{-1} q^+`` written as an increment, so that
round-off does not accumulate in weakly excited directions).  Once
``lambda_max(F) > M`` the law freezes ``F`` for good (``F' = 0`` keeps it
above ``M``) and ``Theta_hat' = gamma F Psi^T (z - Psi Theta_hat)`` is advanced
exactly with :func:`~observers.estimation.gradient.gradient_flow_step`.

Error certificate (:meth:`LeastSquaresForgetting.error_bound`).  For an exact regression
``Y = Phi Theta`` the step above gives ``P+ (Theta_hat+ - Theta) = e^{-beta dt} P (Theta_hat - Theta)``,
so ``P(t) Theta_tilde(t) = e^{-beta t} f0 Theta_tilde(0)`` to round-off, and with a regression
error ``|Y - Phi Theta|_2 <= eps`` on every update (Cauchy-Schwarz on the weighted sum, whose
weights add up to ``gamma (1 - e^{-beta t}) / beta``)

.. math:: |\tilde\Theta(t)|_2 \le \frac{f_0 e^{-\beta t}}{\lambda_{\min}(P)} |\tilde\Theta(0)|_2
          + \varepsilon \sqrt{\frac{\gamma (1 - e^{-\beta t})}{\beta \lambda_{\min}(P)}} .

Once ``F`` is frozen, ``V = Theta_tilde^T P_f Theta_tilde`` does not grow (``eps = 0``), so the
bound at the freeze times ``sqrt(cond P_f)`` holds from then on (``inf`` when ``eps > 0``).
"""

from __future__ import annotations

import math

import numpy as np

from obsfmu.observers.checks import require_positive

from ._validation import dimension, initial_estimate, regression, step_length
from .exponential import phi1
from .gradient import gradient_flow_step

__all__ = ["LeastSquaresForgetting"]


class LeastSquaresForgetting:
    r"""Least-squares estimator with forgetting factor ``beta`` and gain bound ``M`` (paper 001).

    Parameters
    ----------
    p : int
        Number of unknown parameters.
    gamma : float
        Adaptation gain > 0 (``alpha = 1000`` in paper 001's example).
    beta : float
        Forgetting factor > 0 (1 in the example).
    f0 : float
        ``F(0) = I / f0``; > 0 (0.1 in the example).
    M : float
        Bound on the largest eigenvalue of ``F``; > 0 (1e12 in the example).
    theta0 : array_like, optional
        Initial estimate (zeros by default).

    Attributes
    ----------
    theta_hat : ndarray, shape (p,)
        Current estimate.
    P : ndarray, shape (p, p)
        Information matrix ``F^{-1}`` (the integrated state).
    frozen : bool
        True once ``lambda_max(F) > M`` was met at the start of a step; ``F``
        is constant from then on.

    Notes
    -----
    The bound is checked at the start of each step, so ``F`` may exceed
    ``M`` by the growth of one step (a factor ``e^{beta dt}`` at most).
    """

    not_state = ("p", "gamma", "beta", "f0", "M")   # fixed settings (observers.state)
    state_optional = {"_frozen_F": None}             # an array once the gain bound was met

    def __init__(self, p: int, gamma: float, beta: float, f0: float, M: float, theta0=None):
        self.p = dimension("p", p)
        self.gamma = require_positive("gamma", gamma)
        self.beta = require_positive("beta", beta)
        self.f0 = require_positive("f0", f0)
        self.M = require_positive("M", M)
        self.reset(theta0)

    def reset(self, theta0=None) -> None:
        """Restart from ``theta0`` (zeros if omitted) with ``F = I / f0``."""
        self.theta_hat = initial_estimate(theta0, self.p)
        self.P = self.f0 * np.eye(self.p)
        self.lambda_min = self.f0        # smallest eigenvalue of P, kept with P (one eigvalsh per step)
        self.decay = 1.0                 # e^{-beta t} since the reset, until F is frozen
        self._frozen_F = None

    def error_bound(self, initial_error: float, regression_error: float = 0.0) -> float:
        """Guaranteed bound on ``|theta_hat - theta|_2`` (module docstring), given
        ``|theta_hat(0) - theta|_2 <= initial_error`` and ``|Y - Phi theta|_2 <= regression_error``
        on every update; ``inf`` if ``F`` is frozen and ``regression_error > 0``."""
        bound = self.f0 * self.decay * initial_error / self.lambda_min
        if regression_error > 0.0:
            if self.frozen:
                return math.inf
            bound += regression_error * math.sqrt(self.gamma * (1.0 - self.decay) / (self.beta * self.lambda_min))
        if self.frozen:
            eigenvalues = np.linalg.eigvalsh(self.P)
            bound *= math.sqrt(eigenvalues[-1] / eigenvalues[0])
        return bound

    @property
    def F_max(self) -> float:
        """Largest eigenvalue of the gain ``F`` (``1 / lambda_min(P)`` until it is frozen)."""
        return float(np.linalg.eigvalsh(self._frozen_F)[-1]) if self.frozen else 1.0 / self.lambda_min

    @property
    def frozen(self) -> bool:
        return self._frozen_F is not None

    @property
    def F(self) -> np.ndarray:
        """The gain matrix ``F = P^{-1}`` (a copy)."""
        return self._frozen_F.copy() if self.frozen else np.linalg.inv(self.P)

    def update(self, y, phi, dt: float) -> np.ndarray:
        """Advance one step of length ``dt`` with ``y``, ``phi`` held; return ``theta_hat``."""
        Y, Phi = regression(y, phi, self.p)
        dt = step_length(dt)
        frozen_F = self._frozen_F
        if frozen_F is None and self._gain_exceeds_bound():
            frozen_F = np.linalg.inv(self.P)
            frozen_F = 0.5 * (frozen_F + frozen_F.T)
        if frozen_F is None:
            theta, P = self._information_step(Y, Phi, dt)
            lambda_min = float(np.linalg.eigvalsh(P)[0])
            decay = self.decay * math.exp(-self.beta * dt)
        else:
            theta, P = gradient_flow_step(self.theta_hat, Y, Phi, self.gamma, dt, F=frozen_F), self.P
            lambda_min, decay = self.lambda_min, self.decay
        self.theta_hat, self.P, self.lambda_min, self._frozen_F = theta, P, lambda_min, frozen_F
        self.decay = decay
        return self.theta_hat

    def _gain_exceeds_bound(self) -> bool:
        # lambda_max(F) > M  <=>  lambda_min(P) < 1/M
        return self.lambda_min * self.M < 1.0

    def _information_step(self, Y, Phi, dt):
        weight = self.gamma * dt * phi1(self.beta * dt)
        P = math.exp(-self.beta * dt) * self.P + weight * (Phi.T @ Phi)
        P = 0.5 * (P + P.T)
        residual = Y - Phi @ self.theta_hat
        theta = self.theta_hat + weight * np.linalg.solve(P, Phi.T @ residual)
        return theta, P
