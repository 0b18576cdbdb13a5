r"""Continuous DREM and finite-time DREM.

DREM (dynamic regressor extension and mixing, Aranovskiy et al. 2017):

1. extension ``Y_e = Phi_e theta`` (:mod:`~observers.estimation.extension`),
2. mixing ``Y = adj(Phi_e) Y_e = Delta theta`` (:func:`~observers.estimation.mixing.mix`),
3. ``p`` scalar gradients ``theta_i' = gamma_i Delta (Y_i - Delta theta_i)``
   (:func:`~observers.estimation.scalar_gradient.scalar_gradient_step`).

Each parameter error obeys ``theta_tilde_i' = -gamma_i Delta^2 theta_tilde_i``:
it converges iff ``Delta`` is not square-integrable, a condition weaker than
persistent excitation of ``phi``, and monotonically, parameter by parameter.

Normalised gain (optional, ``floor > 0``): ``gamma_i`` is replaced by
``gamma_i / (floor^2 + Delta^2)``, so the error obeys
``theta_tilde_i' = -gamma_i Delta^2 / (floor^2 + Delta^2) theta_tilde_i``:
wherever ``|Delta| >> floor`` each error decays at the rate ``gamma_i``
whatever the size of ``Delta``.  ``Delta`` is a ``p x p`` determinant, so it
shrinks like a power of the signals' size and of the conditioning of the
extension: with the raw gain a rate good for ``p = 2`` is useless at
``p = 6`` (``Delta ~ 1e-8``); with the normalised gain ``gamma`` is a rate in
1/s and ``floor`` the ``|Delta|`` below which adaptation fades (the
normalised DREM of the DREM literature, e.g. Ortega et al. 2020's
``gamma Delta / (1 + Delta^2)`` with the constant 1 as ``floor^2``).

Time discretisation.  One :meth:`DREM.update` takes ``y``, ``phi`` held over
``[t, t + dt]``; the extended regression at ``t`` (start of the step) gives
``Delta`` and ``Y``, held over the step; the scalar laws are advanced exactly
for them, then the extension's filters are advanced exactly for the held
input.  The extended regression stays exact at every sample, so the error
identity ``theta_tilde(t_k) = exp(-gamma sum Delta_j^2 dt) theta_tilde(0)``
holds to round-off.
"""

from __future__ import annotations

import numpy as np

from obsfmu.observers.checks import ParameterError

from ._validation import initial_estimate, positive_gains, regression, step_length
from .mixing import mix
from .scalar_gradient import finite_time_estimate, scalar_gradient_step

__all__ = ["DREM", "FiniteTimeDREM"]


def _check_extension(extension) -> None:
    missing = [name for name in ("p", "rows", "extend", "advance", "reset") if not hasattr(extension, name)]
    if missing:
        raise ParameterError(
            f"extension: expected an extension object (KreisselmeierExtension, FilterBankExtension, "
            f"DelayExtension, ...), {type(extension).__name__} lacks {', '.join(missing)}"
        )


class DREM:
    r"""Continuous DREM estimator.

    Parameters
    ----------
    extension : extension object
        :class:`~observers.estimation.FilterBankExtension`,
        :class:`~observers.estimation.KreisselmeierExtension`,
        :class:`~observers.estimation.DelayExtension` (or any object with the
        same interface).  It fixes ``p``.  The estimator owns it from now on
        (:meth:`reset` resets it).
    gamma : float or array_like, shape (p,)
        Gains ``gamma_i > 0`` of the scalar laws.
    normalize : bool, default True
        Row-normalise the extended regression before mixing, so
        ``|Delta| <= 1`` (needed for larger ``p``; see
        :mod:`~observers.estimation.mixing`).  ``False`` gives the raw
        ``Delta = det(Phi_e)`` of the papers.
    theta0 : array_like, optional
        Initial estimate (zeros by default).

    Attributes
    ----------
    theta_hat : ndarray, shape (p,)
        Current estimate.
    delta : float
        ``Delta`` used in the last step (0 before the first).
    """

    not_state = ("p", "gamma", "normalize", "floor")       # fixed settings (observers.state)

    def __init__(self, extension, gamma, normalize: bool = True, theta0=None, floor: float = 0.0):
        _check_extension(extension)
        self.extension = extension
        self.p = extension.p
        self.gamma = positive_gains("gamma", gamma, self.p)
        self.normalize = bool(normalize)
        self.floor = float(floor)
        if not (np.isfinite(self.floor) and self.floor >= 0):
            raise ParameterError(f"floor: expected a finite number >= 0 (0: the raw gain), got {floor!r}")
        self.reset(theta0)

    def gain(self, delta: float) -> np.ndarray:
        """The gains ``gamma_i`` of the scalar laws at ``Delta``: raw, or ``gamma_i / (floor^2 + Delta^2)``."""
        if self.floor == 0.0:
            return self.gamma
        return self.gamma / (self.floor * self.floor + delta * delta)

    def reset(self, theta0=None) -> None:
        """Restart from ``theta0`` (zeros if omitted) with zero extension state."""
        self.theta_hat = initial_estimate(theta0, self.p)
        self.delta = 0.0
        self.extension.reset()

    def update(self, y, phi, dt: float) -> np.ndarray:
        """Advance one step of length ``dt`` with ``y``, ``phi`` held; return ``theta_hat``."""
        Y, Phi = regression(y, phi, self.p, self.extension.rows)
        dt = step_length(dt)
        mixed, delta = mix(*self.extension.extend(Y, Phi), normalize=self.normalize)
        theta = scalar_gradient_step(self.theta_hat, mixed, delta, self.gain(delta), dt)
        self.extension.advance(Y, Phi, dt)
        self.theta_hat, self.delta = theta, delta
        return self.theta_hat


class FiniteTimeDREM:
    r"""Finite-time DREM (Ortega et al. 2020; paper 003, eqs. (11)-(12), paper 004).

    The DREM gradient (:class:`DREM`) plus, per parameter,

    .. math::
        \dot\nu_i = -\gamma_i \Delta^2 \nu_i,\quad \nu_i(0) = 1, \qquad
        \theta^*_i = \frac{\hat\theta_i - \nu_{c,i}\,\hat\theta_i(0)}{1 - \nu_{c,i}},
        \quad \nu_{c,i} = \min(\nu_i, \mu_i).

    ``nu`` is advanced exactly (``nu *= exp(-gamma Delta^2 dt)``), with the
    same ``Delta`` as the gradient, so the identity
    ``theta_tilde_i = nu_i theta_tilde_i(0)`` holds to round-off and
    ``theta*`` is exact from the first sample with ``nu_i < mu_i`` on.

    Parameters
    ----------
    extension, gamma, normalize, theta0
        As for :class:`DREM`.
    mu : float or array_like, shape (p,)
        Switching levels in (0, 1); paper 003 uses 0.98.  A smaller ``mu``
        switches later but divides round-off by ``1 - mu`` only.

    Attributes
    ----------
    theta_hat : ndarray, shape (p,)
        The finite-time estimate ``theta*``.
    theta_drem : ndarray, shape (p,)
        The underlying (asymptotic) DREM estimate ``theta_hat``.
    nu : ndarray, shape (p,)
    time : float
        Sum of the steps since the last reset.
    switch_time : float or None
        ``time`` at the end of the first step after which ``nu_i < mu_i``
        for every ``i``; ``None`` before.
    converged : bool
        ``switch_time is not None``.
    """

    not_state = ("p", "mu")
    state_optional = {"switch_time": None}

    def __init__(self, extension, gamma, mu, normalize: bool = True, theta0=None):
        self.drem = DREM(extension, gamma, normalize=normalize, theta0=theta0)
        self.p = self.drem.p
        self.mu = positive_gains("mu", mu, self.p)
        if np.any(self.mu >= 1.0):
            raise ParameterError(f"mu: entries must lie in (0, 1), got {self.mu.tolist()}")
        self.reset(theta0)

    @property
    def gamma(self) -> np.ndarray:
        return self.drem.gamma

    @property
    def extension(self):
        return self.drem.extension

    @property
    def theta_drem(self) -> np.ndarray:
        return self.drem.theta_hat

    @property
    def delta(self) -> float:
        return self.drem.delta

    @property
    def converged(self) -> bool:
        return self.switch_time is not None

    def reset(self, theta0=None) -> None:
        """Restart from ``theta0`` (zeros if omitted), ``nu = 1``, time 0."""
        self.drem.reset(theta0)
        self.theta0 = self.drem.theta_hat.copy()
        self.theta_hat = self.theta0.copy()
        self.nu = np.ones(self.p)
        self.time = 0.0
        self.switch_time = None

    def update(self, y, phi, dt: float) -> np.ndarray:
        """Advance one step of length ``dt`` with ``y``, ``phi`` held; return ``theta*``."""
        dt = step_length(dt)
        self.drem.update(y, phi, dt)            # validates and raises before any change
        self.nu = self.nu * np.exp(-self.drem.gain(self.delta) * (self.delta * self.delta * dt))
        self.time += dt
        if self.switch_time is None and np.all(self.nu < self.mu):
            self.switch_time = self.time
        self.theta_hat = finite_time_estimate(self.drem.theta_hat, self.theta0, self.nu, self.mu)
        return self.theta_hat
