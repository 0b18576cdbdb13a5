r"""Continuous gradient estimator of a linear regression.

Regression ``y = phi^T theta`` (or ``Y = Phi theta``); estimator

.. math:: \dot{\hat\theta} = \gamma\,\Phi^T (Y - \Phi \hat\theta)

with the optional normalisation ``gamma -> gamma / (1 + |Phi|_F^2)``.  It
converges exponentially when ``phi`` is persistently exciting (PE) and may
stall otherwise; it is the reference the DREM estimators are compared with.
"""

from __future__ import annotations

import numpy as np

from obsfmu.observers.checks import require_positive

from ._validation import dimension, initial_estimate, regression, step_length
from .exponential import phi1_symmetric

__all__ = ["Gradient", "gradient_flow_step"]


def gradient_flow_step(theta, Y, Phi, gamma: float, dt: float, F=None) -> np.ndarray:
    r"""Exact step of ``theta' = gamma F Phi^T (Y - Phi theta)`` for ``Y``, ``Phi`` (and ``F``) held.

    The residual ``r = Y - Phi theta`` obeys ``r' = -gamma Phi F Phi^T r``, so

    .. math:: \theta(t + dt) = \theta + \gamma\,dt\,F\Phi^T\,
              \varphi_1(\gamma\,dt\,\Phi F \Phi^T)\,r(t).

    Parameters
    ----------
    theta : ndarray, shape (p,)
    Y : ndarray, shape (m,)
    Phi : ndarray, shape (m, p)
    gamma, dt : float
        Gain > 0 and step > 0.
    F : ndarray, shape (p, p), optional
        Symmetric positive semi-definite gain matrix; identity if omitted.

    Returns
    -------
    ndarray, shape (p,)
        The new estimate (a new array; ``theta`` is not modified).
    """
    residual = Y - Phi @ theta
    gain_columns = Phi.T if F is None else F @ Phi.T          # F Phi^T, shape (p, m)
    stiffness = gamma * dt * (Phi @ gain_columns)             # gamma dt Phi F Phi^T, (m, m)
    stiffness = 0.5 * (stiffness + stiffness.T)
    return theta + gamma * dt * (gain_columns @ (phi1_symmetric(stiffness) @ residual))


class Gradient:
    r"""Gradient estimator ``theta_hat' = gamma phi (y - phi^T theta_hat)``.

    Parameters
    ----------
    p : int
        Number of unknown parameters.
    gamma : float
        Adaptation gain > 0.
    normalize : bool, default False
        Use ``gamma / (1 + |Phi|_F^2)`` (normalised gradient), which bounds the
        rate for large regressors.
    theta0 : array_like, optional
        Initial estimate (zeros by default).

    Attributes
    ----------
    theta_hat : ndarray, shape (p,)
        Current estimate.

    Notes
    -----
    One :meth:`update` is the exact solution over ``dt`` for ``y``, ``phi``
    held (:func:`gradient_flow_step`), so any ``gamma |phi|^2 dt`` is stable.
    Vector regressions ``Y = Phi theta`` use ``Phi^T (Y - Phi theta)``.
    """

    def __init__(self, p: int, gamma: float, normalize: bool = False, theta0=None):
        self.p = dimension("p", p)
        self.gamma = require_positive("gamma", gamma)
        self.normalize = bool(normalize)
        self.reset(theta0)

    def reset(self, theta0=None) -> None:
        """Restart from ``theta0`` (zeros if omitted)."""
        self.theta_hat = initial_estimate(theta0, self.p)

    def update(self, y, phi, dt: float) -> np.ndarray:
        """Advance one step of length ``dt`` with ``y``, ``phi`` held; return ``theta_hat``."""
        Y, Phi = regression(y, phi, self.p)
        dt = step_length(dt)
        gain = self.gamma / (1.0 + np.sum(Phi * Phi)) if self.normalize else self.gamma
        self.theta_hat = gradient_flow_step(self.theta_hat, Y, Phi, gain, dt)
        return self.theta_hat
