r"""Stage 4: the state from an observer of the identified plant (paper 003, closing paragraph).

The paper's state estimate (8) needs ``y^(r-1)`` (Statement 1 assumes the
derivatives are measured).  Its closing paragraph: once ``theta`` and ``f``
are identified, build a classical observer of (1).  Here a Luenberger
observer started at ``t_0``

.. math:: \dot{\hat x} = (A + B\hat\theta^T - K C)\,\hat x + B \hat f(t) + K y,
          \qquad \hat x(t_0) = \bar z(t_0) + G_0\, y(t_0),

and, as in Statement 1, an FT-DREM on its initial error: with
``Psi' = (A + B theta^T - K C) Psi``, ``Psi(t_0) = I``,

.. math:: y - C\hat x = C\,\Psi(t)\, e(t_0), \qquad
          x \approx \hat x + \Psi(t)\, \hat e(t_0),

exact once the identification is exact and the FT-DREM has switched.  ``K``
places ``eig(A + B theta_hat^T - K C)`` at ``eig(F)`` (the observer poles of
the design).  ``x_hat`` and ``Psi`` are advanced with RK4 (the dynamics are
slow, rates ~ |eig(F)|; one sub-step per 0.01/rate).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from obsfmu.observers.checks import ParameterError
from obsfmu.observers.estimation import FilterBankExtension, FiniteTimeDREM
from obsfmu.observers.integrators import DEFAULT_SUBSTEP_BUDGET, rk4_step, substep_count
from obsfmu.observers.modal import observer_gain

__all__ = ["IdentifiedPlantObserver"]


class IdentifiedPlantObserver:
    """Luenberger observer of the identified plant plus FT-DREM on its initial error.

    Parameters
    ----------
    A, B, C : plant matrices (``B``, ``C`` 1-D)
    theta : (n,) ndarray
        Identified ``theta`` at the start (fixes ``K``).
    poles : (n,) array_like
        Poles of ``A + B theta^T - K C`` (``eig(F)``).
    x_hat0 : (n,) ndarray
        ``x_hat(t_0)``.
    rates, gamma, mu, normalize
        Extension filter rates and FT-DREM settings for ``e(t_0)``.
    substep_budget : int
        Most RK4 sub-steps one step may take (a longer step is refused before any work).
    """

    not_state = ("A", "B", "C", "substep_budget")

    def __init__(self, A, B, C, theta, poles, x_hat0, rates, gamma, mu, normalize,
                 substep_budget: int = DEFAULT_SUBSTEP_BUDGET):
        self.A, self.B, self.C = A, B, C
        n = A.shape[0]
        try:
            self.K = observer_gain(A + np.outer(B, theta), C[None, :], poles).ravel()
        except ParameterError:
            self.K = np.zeros(n)      # (A + B theta^T, C) unobservable: open loop, FT-DREM still corrects
        self.x_hat = np.array(x_hat0, dtype=float)
        self.Psi = np.eye(n)
        self.drem = FiniteTimeDREM(FilterBankExtension(rates), gamma, mu, normalize=normalize)
        self.substep_budget = substep_budget

    @property
    def estimate(self) -> np.ndarray:
        """``x_hat + Psi e_hat(t_0)``."""
        return self.x_hat + self.Psi @ self.drem.theta_hat

    def _closed_loop(self, theta: np.ndarray) -> np.ndarray:
        return self.A + np.outer(self.B, theta) - np.outer(self.K, self.C)

    def advance(self, t: float, h: float, y0: float, dy: float, theta: np.ndarray | Callable[[float], np.ndarray],
                f_hat: Callable[[float], float], adapt: bool = True) -> None:
        """Step ``[t, t + h]`` with ``y(t + s) = y0 + s dy`` and the current identified model.

        ``theta``: the identified parameters, or ``s -> theta_hat(s)`` for a time-varying ``theta``
        (``H e^{Gamma s} xi0_hat``; then ``A + B theta^T - K C`` and ``Psi`` follow it inside the step).
        ``adapt=False`` keeps ``e_hat(t_0)`` (the stage is identified).
        """
        C = self.C
        varying = callable(theta)
        A_K = self._closed_loop(theta(t) if varying else theta)
        rate = np.linalg.norm(A_K)                       # Frobenius: bounds |eig|, no SVD
        substeps = substep_count(h, rate=rate, max_change=0.01, budget=self.substep_budget)
        if adapt:
            self.drem.update(y0 - C @ self.x_hat, C @ self.Psi, h)
        n = self.A.shape[0]

        def rhs(s, state):
            x_hat, Psi = state[:n], state[n:].reshape(n, n)
            A_s = self._closed_loop(theta(s)) if varying else A_K
            dx = A_s @ x_hat + self.B * f_hat(s) + self.K * (y0 + (s - t) * dy)
            return np.concatenate([dx, (A_s @ Psi).ravel()])

        state = rk4_step(rhs, t, np.concatenate([self.x_hat, self.Psi.ravel()]), h, substeps)
        self.x_hat, self.Psi = state[:n], state[n:].reshape(n, n)
