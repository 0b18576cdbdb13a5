r"""The per-parameter laws of DREM: ``p`` decoupled scalar regressions ``Y_i = Delta theta_i``.

Shared by :class:`~observers.estimation.DREM`,
:class:`~observers.estimation.FiniteTimeDREM`,
:class:`~observers.estimation.DiscreteDREM` and by the observers that mix
their own regressions (papers 000, 003, 004).
"""

from __future__ import annotations

import numpy as np

from .exponential import phi1

__all__ = ["scalar_gradient_step", "discrete_scalar_gradient_step", "finite_time_estimate"]


def scalar_gradient_step(theta, Y, delta: float, gamma, dt: float) -> np.ndarray:
    r"""Exact step of ``theta_i' = gamma_i Delta (Y_i - Delta theta_i)`` for ``Delta``, ``Y`` held.

    DREM gradient (paper 003, eq. (11); paper 004, estimator after eq. (7)):

    .. math:: \theta_i(t + dt) = \theta_i + \gamma_i\,dt\,
              \varphi_1(\gamma_i \Delta^2 dt)\,\Delta\,(Y_i - \Delta\theta_i)

    Stable and accurate for any ``gamma Delta^2 dt``: tiny (``phi1 -> 1``, an
    Euler step without cancellation) or huge (``-> Y_i / Delta``, computed
    without dividing by ``Delta``).  With ``Y = Delta theta`` the error obeys
    ``theta_tilde_i(t + dt) = exp(-gamma_i Delta^2 dt) theta_tilde_i(t)``.

    Parameters
    ----------
    theta, Y : ndarray, shape (p,)
    delta : float
    gamma : float or ndarray, shape (p,)
    dt : float

    Returns
    -------
    ndarray, shape (p,)
        New estimate (``theta`` is not modified).
    """
    return theta + gamma * dt * phi1(gamma * (delta * delta * dt)) * delta * (Y - delta * theta)


def discrete_scalar_gradient_step(theta, Y, delta: float, k) -> np.ndarray:
    r"""One sample of the discrete DREM law (paper 000, Statement 2).

    .. math:: \theta_i(k) = \theta_i(k-1) + \frac{\Delta(k)}{k_i + \Delta^2(k)}
              \bigl(Y_i(k) - \Delta(k)\,\theta_i(k-1)\bigr)

    With ``Y = Delta theta`` the error obeys
    ``theta_tilde_i(k) = theta_tilde_i(k-1) / (1 + Delta^2 / k_i)``.

    Parameters
    ----------
    theta, Y : ndarray, shape (p,)
    delta : float
    k : float or ndarray, shape (p,)
        Gains ``k_i > 0``.
    """
    return theta + delta / (k + delta * delta) * (Y - delta * theta)


def finite_time_estimate(theta_hat, theta0, nu, mu) -> np.ndarray:
    r"""Finite-time DREM estimate (Ortega et al. 2020; paper 003, eq. (12)).

    .. math:: \theta^* = \frac{\hat\theta - \nu_c\,\hat\theta(0)}{1 - \nu_c},
              \qquad \nu_c = \min(\nu, \mu),

    where ``nu' = -gamma Delta^2 nu``, ``nu(0) = 1``, ``mu in (0, 1)``.  Since
    ``theta_tilde(t) = nu(t) theta_tilde(0)``, ``theta* = theta`` exactly
    once ``nu < mu``.

    Parameters
    ----------
    theta_hat : ndarray, shape (p,)
        The DREM gradient estimate.
    theta0 : ndarray, shape (p,)
        Its initial value ``theta_hat(0)``.
    nu, mu : float or ndarray, shape (p,)
    """
    nu_c = np.minimum(nu, mu)
    return (theta_hat - nu_c * theta0) / (1.0 - nu_c)
