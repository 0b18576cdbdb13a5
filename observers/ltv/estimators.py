r"""The estimators the observer of paper 001 may use for regression (7), each with its diagnostics.

The shared estimators of :mod:`observers.estimation`, each given what the observer needs of it:

* ``forgetting``: the rate that weights the regression rows inside a step (:func:`_quadrature_weights`
  of the observer integrates ``int exp(-forgetting (h - s)) Psi^T Psi ds`` by Gauss quadrature);
* ``excitation``: the family's measure of the excitation so far (>= 0);
* ``error_bound(initial_error, regression_error)``: a guaranteed bound on ``|Theta_hat - Theta|_2``
  given ``|Theta_hat(0) - Theta|_2 <= initial_error`` (the ``converged`` flag's criterion).

``least-squares`` (the paper's): :class:`~observers.estimation.LeastSquaresForgetting`; excitation
``lambda_min(P) / gamma``; its own bound, which also covers a bounded regression error.

``drem``: :class:`~observers.estimation.DREM` on a Kreisselmeier extension of rate ``a``
(``Phi_e' = -a Phi_e + Psi^T Psi``, row-normalised mixing, so ``|Delta| <= 1``) with the normalised gain
``g = gamma / (delta_floor^2 + Delta^2)`` (``delta_floor = 0``: the raw ``g = gamma``); each error obeys
``theta_tilde_i' = -g Delta^2 theta_tilde_i`` exactly at the samples (``Delta`` held over a step),
so ``|theta_tilde_i(t)| = nu_i |theta_tilde_i(0)|``, ``nu_i = exp(-int g Delta^2)``; excitation
``|Delta|`` of the last step; bound ``max_i nu_i * initial_error``.  Normalised, ``gamma`` is the rate
(1/s) of every error while ``|Delta| >> delta_floor``, whatever the number of unknowns (``Delta`` of 6
unknowns is ~1e-8 where that of 2 is ~1e-2).

``gradient``: :class:`~observers.estimation.Gradient`, ``Theta_hat' = gamma Psi^T (z - Psi Theta_hat)``;
the error obeys ``theta_tilde' = -gamma Psi^T Psi theta_tilde``, so it is ``T(t) theta_tilde(0)`` with
the transition matrix ``T`` advanced by the same exact step; bound ``|T|_2 * initial_error``,
excitation ``1 - |T|_2`` (the guaranteed fraction of the initial error removed so far, 0 to 1).

DREM's and the gradient's bounds hold for an exact regression only (no noise); a nonzero
``regression_error`` is refused for them.
"""

from __future__ import annotations

import copy

import numpy as np

from ..checks import ParameterError, require_positive
from ..estimation import DREM, Gradient, KreisselmeierExtension, LeastSquaresForgetting, gradient_flow_step

__all__ = ["DELTA_FLOOR", "ESTIMATORS", "make_estimator", "require_exact"]

#: the estimator names, the paper's first
ESTIMATORS = ("least-squares", "drem", "gradient")

#: DREM's default |Delta| below which the normalised gain fades.  The estimate moves towards Y / Delta, so the
#: regression's own error (1e-7 relative at 1e-2 s steps) is amplified by 1 / Delta: measured on the
#: mass-spring-damper, 1e-7 let a 1.05e-3 error be flagged converged at tolerance 1e-3; 1e-6 keeps every flagged
#: error below 3.1e-4 and still converges with 4 unknowns in 1.3 s (raw gain: 21.9 s) and 6 in 9.3 s (raw: never)
DELTA_FLOOR = 1e-6


class _LeastSquares(LeastSquaresForgetting):
    @property
    def forgetting(self) -> float:
        return self.beta

    @property
    def excitation(self) -> float:
        return self.lambda_min / self.gamma


class _DREM(DREM):
    def __init__(self, p: int, gamma: float, rate: float, theta0, delta_floor: float):
        self.forgetting = require_positive("extension_rate", rate)
        super().__init__(KreisselmeierExtension(p, self.forgetting), gamma, normalize=True, theta0=theta0,
                         floor=require_positive("delta_floor", delta_floor, allow_zero=True))
        self.nu = np.ones(self.p)

    not_state = ("forgetting",)

    def __copy__(self):
        twin = object.__new__(type(self))
        twin.__dict__.update(self.__dict__)
        twin.extension = copy.copy(self.extension)      # its filters advance in update
        return twin

    @property
    def excitation(self) -> float:
        return abs(self.delta)

    def update(self, y, phi, dt: float) -> np.ndarray:
        super().update(y, phi, dt)
        self.nu = self.nu * np.exp(-self.gain(self.delta) * self.delta ** 2 * dt)
        return self.theta_hat

    def error_bound(self, initial_error: float, regression_error: float = 0.0) -> float:
        return float(self.nu.max()) * initial_error


class _Gradient(Gradient):
    forgetting = 0.0

    def __init__(self, p: int, gamma: float, theta0):
        super().__init__(p, gamma, theta0=theta0)
        self.transition = np.eye(self.p)

    @property
    def _contraction(self) -> float:
        return float(np.linalg.norm(self.transition, 2))

    @property
    def excitation(self) -> float:
        return max(0.0, 1.0 - self._contraction)

    def update(self, y, phi, dt: float) -> np.ndarray:
        super().update(y, phi, dt)
        Phi = np.atleast_2d(np.asarray(phi, dtype=float))
        self.transition = gradient_flow_step(self.transition, np.zeros((Phi.shape[0], self.p)), Phi, self.gamma, dt)
        return self.theta_hat

    def error_bound(self, initial_error: float, regression_error: float = 0.0) -> float:
        return self._contraction * initial_error


def require_exact(name: str, regression_error_bound: float) -> None:
    """Refuse a regression error bound for an estimator whose ``converged`` bound assumes none."""
    if name != ESTIMATORS[0] and regression_error_bound > 0:
        raise ParameterError(f"regression_error_bound: the {name} estimator's converged bound holds for an exact "
                             "regression only; give 0, or use the least-squares estimator")


def make_estimator(name: str, theta0: np.ndarray, gamma: float, beta: float, f0: float, M: float,
                   extension_rate: float, regression_error_bound: float, delta_floor: float = DELTA_FLOOR):
    """The estimator ``name`` (one of :data:`ESTIMATORS`) of ``theta0.size`` unknowns from ``theta0``."""
    if name not in ESTIMATORS:
        raise ParameterError(f"estimator: expected one of {list(ESTIMATORS)}, got {name!r}")
    require_exact(name, regression_error_bound)
    if name == "least-squares":
        return _LeastSquares(theta0.size, gamma, beta, f0, M, theta0)
    if name == "drem":
        return _DREM(theta0.size, gamma, extension_rate, theta0, delta_floor)
    return _Gradient(theta0.size, gamma, theta0)
