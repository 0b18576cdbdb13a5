r"""GPEBO filters of paper 000, Statement 1: ``x = phi_x eta``, ``y = phi_y eta`` (3)-(4).

For the plant ``x(k+1) = A x(k) + D(u(k), y(k)) xi(k)``, ``xi(k+1) = Gamma xi(k)``
(:mod:`observers.gpebo.model`), started at sample ``t0``:

.. math::
    \Phi(k+1) = \Gamma \Phi(k),\; \Phi(t_0) = I, \qquad
    \varphi_x(k+1) = A \varphi_x(k) + D(u(k), y(k))\, \Phi(k),\; \varphi_x(t_0) = 0 .

The column blocks of ``phi_x`` are the paper's ``g``, ``Y``, ``w``.  With
``eta = xi(t0)`` (6) the error ``e = x - phi_x eta`` obeys ``e(k+1) = A e(k)``
(proof of Statement 1), so ``e(k) = A^(k - t0) x(t0)`` vanishes after ``n``
samples (``A`` is nilpotent): ``x(k) = phi_x(k) eta`` and
``y(k) = phi_y(k) eta``, ``phi_y = C^T phi_x``, exactly for ``k >= t0 + n``.

Restarts.  ``Gamma`` is the *estimated* generator matrix.  When it changes the
filters restart at the current sample with ``eta = xi(t0)`` the new unknown.
To keep the state estimate continuous across a restart we also carry
``e_hat(k+1) = A e_hat(k)``, ``e_hat(t0) = x_hat(t0)`` (the estimate just
before the restart), so ``x_hat = phi_x eta_hat + e_hat``; ``e_hat`` vanishes
after ``n`` samples like ``e``.
"""

from __future__ import annotations

import numpy as np

from .model import GeneratorModel, shift_matrix

__all__ = ["GpeboFilters"]


class GpeboFilters:
    """The filters ``Phi``, ``phi_x`` (= ``[g, Y, w]``) and ``e_hat`` of Statement 1.

    Parameters
    ----------
    model : GeneratorModel
    Gamma : ndarray, shape (N, N)
        Generator matrix used by the filters (an estimate).
    x_start : ndarray, shape (n,)
        ``e_hat(t0)``: the state estimate at the start.
    """

    not_state = ("model", "A")

    def __init__(self, model: GeneratorModel, Gamma: np.ndarray, x_start: np.ndarray):
        self.model = model
        self.A = shift_matrix(model.n)
        self.restart(Gamma, x_start)

    def restart(self, Gamma: np.ndarray, x_start: np.ndarray) -> None:
        """Start again at the current sample: ``Phi = I``, ``phi_x = 0``, ``e_hat = x_start``."""
        N = self.model.N
        self.Gamma = np.array(Gamma, dtype=float)
        self.Phi = np.eye(N)
        self.phi_x = np.zeros((self.model.n, N))
        self.e_hat = np.array(x_start, dtype=float)
        self.age = 0  #: samples since the (re)start

    @property
    def phi_y(self) -> np.ndarray:
        """Regressor ``phi_y = C^T phi_x`` of ``y = phi_y eta`` (4), ``C = e_1``."""
        return self.phi_x[0]

    @property
    def exact(self) -> bool:
        """True once ``y = phi_y eta`` holds exactly (``n`` samples after the start)."""
        return self.age >= self.model.n

    def state_estimate(self, eta_hat: np.ndarray) -> np.ndarray:
        """``x_hat = phi_x eta_hat + e_hat`` (step 3, eq. (3))."""
        return self.phi_x @ eta_hat + self.e_hat

    def generator_estimate(self, eta_hat: np.ndarray) -> np.ndarray:
        """``xi_hat(k) = Phi(k) eta_hat``: the current generator states."""
        return self.Phi @ eta_hat

    def advance(self, u: float, y: float) -> None:
        """One sample with ``u(k)``, ``y(k)`` (computes everything before assigning)."""
        D = self.model.input_matrix(u, y)
        phi_x = self.A @ self.phi_x + D @ self.Phi
        Phi = self.Gamma @ self.Phi
        self.phi_x, self.Phi, self.e_hat, self.age = phi_x, Phi, self.A @ self.e_hat, self.age + 1
