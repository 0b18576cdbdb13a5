r"""Discrete-time DREM with delay extension (paper 000, eqs. (17)-(19), Statement 2).

For the sampled regression ``psi(k) = M^T(k) eta`` (17):

1. delays: ``theta_e(k) = Y_e(k) eta`` with rows ``k, k - v_1, ...`` (18),
   :class:`~observers.estimation.DelayExtension`;
2. mixing: ``theta(k) = adj(Y_e(k)) theta_e(k) = Delta(k) eta`` (19),
   :func:`~observers.estimation.mixing.mix`;
3. Statement 2, per parameter:
   ``eta_i(k) = eta_i(k-1) + Delta/(k_i + Delta^2) (theta_i - Delta eta_i(k-1))``,
   :func:`~observers.estimation.scalar_gradient.discrete_scalar_gradient_step`.

The error obeys ``eta_tilde_i(k) = eta_tilde_i(k-1) / (1 + Delta^2(k)/k_i)``.
"""

from __future__ import annotations

import numpy as np

from obsfmu.observers.checks import ParameterError

from ._validation import initial_estimate, positive_gains, regression
from .extension import DelayExtension
from .mixing import mix
from .scalar_gradient import discrete_scalar_gradient_step

__all__ = ["DiscreteDREM"]


class DiscreteDREM:
    r"""Discrete DREM estimator of paper 000 (Statement 2).

    Parameters
    ----------
    extension : DelayExtension
        Delays in samples; fixes ``p``.  Owned by the estimator from now on.
    k : float or array_like, shape (p,)
        Gains ``k_i > 0`` (smaller is faster; ``k_i -> 0`` solves
        ``Y_i = Delta eta_i`` in one sample).
    normalize : bool, default True
        Row-normalise before mixing so ``|Delta| <= 1`` whatever the scale
        of the signals; needed for ``p = 10`` (paper 000's example).  Then
        ``k_i`` is relative to ``Delta^2 <= 1``.
    theta0 : array_like, optional
        Initial estimate (zeros by default).

    Attributes
    ----------
    theta_hat : ndarray, shape (p,)
    delta : float
        ``Delta(k)`` of the last sample.
    samples : int
        Number of samples processed since the last reset.

    Notes
    -----
    :meth:`update` advances one sample.  Its ``dt`` argument exists for a
    uniform interface only: omit it or pass 1 (one sample); any other value
    raises :class:`~observers.checks.ParameterError`, since a discrete law
    cannot be stretched to another step.
    """

    not_state = ("p", "k", "normalize")       # fixed settings (observers.state)

    def __init__(self, extension, k, normalize: bool = True, theta0=None):
        if not isinstance(extension, DelayExtension):
            raise ParameterError(
                f"extension: DiscreteDREM needs a DelayExtension (delays in samples), got {type(extension).__name__}"
            )
        self.extension = extension
        self.p = extension.p
        self.k = positive_gains("k", k, self.p)
        self.normalize = bool(normalize)
        self.reset(theta0)

    def reset(self, theta0=None) -> None:
        """Restart from ``theta0`` (zeros if omitted) with an empty delay line."""
        self.theta_hat = initial_estimate(theta0, self.p)
        self.delta = 0.0
        self.samples = 0
        self.extension.reset()

    def update(self, y, phi, dt=None) -> np.ndarray:
        """Process sample ``k`` of ``y``, ``phi``; return ``theta_hat(k)``."""
        if dt is not None and dt != 1:
            raise ParameterError(f"dt: DiscreteDREM advances one sample per update; omit dt or pass 1, got {dt!r}")
        Y, Phi = regression(y, phi, self.p, self.extension.rows)
        mixed, delta = mix(*self.extension.extend(Y, Phi), normalize=self.normalize)
        theta = discrete_scalar_gradient_step(self.theta_hat, mixed, delta, self.k)
        self.extension.advance(Y, Phi)
        self.theta_hat, self.delta = theta, delta
        self.samples += 1
        return self.theta_hat
