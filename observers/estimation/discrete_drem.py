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

Round-off floor (optional, ``relative_floor > 0``).  With a tiny ``k_i`` every sample solves
``Y_i = Delta eta_i`` outright, also one whose ``Delta`` is near round-off: ``Y_i / Delta`` then carries the
round-off of ``Y_i`` divided by ``Delta``, and an estimate right to 1e-15 jumps to 1e-11 (a full-gamma GPEBO
regression of ``p = 47`` unknowns: ``|Delta|`` from 1e-5 down to 3e-14 on exact data).  The floor uses
``k_i' = max(k_i, relative_floor Delta_max^2)``, ``Delta_max`` the largest ``|Delta|`` since the reset: a
sample far weaker than the best one seen barely moves the estimate, and the error identity holds with
``k_i'`` (:attr:`contraction`).  ``relative_floor = 0`` is the paper's law.
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
    relative_floor : float, default 0
        ``k_i' = max(k_i, relative_floor Delta_max^2)`` (module docstring); 0: Statement 2 as printed.

    Attributes
    ----------
    theta_hat : ndarray, shape (p,)
    delta : float
        ``Delta(k)`` of the last sample.
    samples : int
        Number of samples processed since the last reset.
    delta_max : float
        The largest ``|Delta|`` since the last reset.

    Notes
    -----
    :meth:`update` advances one sample.  Its ``dt`` argument exists for a
    uniform interface only: omit it or pass 1 (one sample); any other value
    raises :class:`~observers.checks.ParameterError`, since a discrete law
    cannot be stretched to another step.
    """

    not_state = ("p", "k", "normalize", "relative_floor")       # fixed settings (observers.state)
    state_optional = {"delta_max": 0.0}                          # states saved before the floor existed

    def __init__(self, extension, k, normalize: bool = True, theta0=None, relative_floor: float = 0.0):
        if not isinstance(extension, DelayExtension):
            raise ParameterError(
                f"extension: DiscreteDREM needs a DelayExtension (delays in samples), got {type(extension).__name__}"
            )
        self.extension = extension
        self.p = extension.p
        self.k = positive_gains("k", k, self.p)
        self.normalize = bool(normalize)
        self.relative_floor = float(relative_floor)
        if not (np.isfinite(self.relative_floor) and 0.0 <= self.relative_floor < 1.0):
            raise ParameterError(f"relative_floor: expected a number in [0, 1), got {relative_floor!r}")
        self.reset(theta0)

    def reset(self, theta0=None) -> None:
        """Restart from ``theta0`` (zeros if omitted) with an empty delay line."""
        self.theta_hat = initial_estimate(theta0, self.p)
        self.delta = 0.0
        self.delta_max = 0.0
        self.samples = 0
        self.extension.reset()

    def _gains(self, delta_max: float) -> np.ndarray:
        return np.maximum(self.k, self.relative_floor * delta_max * delta_max)

    @property
    def contraction(self) -> np.ndarray:
        """``k_i' / (k_i' + Delta^2)`` of the last sample: ``eta_tilde_i(k) = contraction_i eta_tilde_i(k-1)``."""
        k = self._gains(self.delta_max)
        return k / (k + self.delta * self.delta)

    def update(self, y, phi, dt=None) -> np.ndarray:
        """Process sample ``k`` of ``y``, ``phi``; return ``theta_hat(k)``."""
        if dt is not None and dt != 1:
            raise ParameterError(f"dt: DiscreteDREM advances one sample per update; omit dt or pass 1, got {dt!r}")
        Y, Phi = regression(y, phi, self.p, self.extension.rows)
        mixed, delta = mix(*self.extension.extend(Y, Phi), normalize=self.normalize)
        delta_max = max(self.delta_max, abs(delta))
        theta = discrete_scalar_gradient_step(self.theta_hat, mixed, delta, self._gains(delta_max))
        self.extension.advance(Y, Phi)
        self.theta_hat, self.delta, self.delta_max = theta, delta, delta_max
        self.samples += 1
        return self.theta_hat
