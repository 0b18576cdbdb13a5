r"""Statements 1-2 of paper 004: auxiliary filters and the linear regression in ``chi(t)``.

Derivation (the paper gives only its outline).  Filter relation (3) with ``a / (p + a)``,
``a > 0``, zero initial conditions (``p = d/dt``):

.. math:: c_f = \phi_{fl}^\top \theta_l + \frac{a}{p + a}\bigl[\phi_\chi^\top \chi\bigr],
          \qquad c_f = \frac{a}{p + a}[c],\
          \phi_f = \frac{a}{p + a}[\phi] = \operatorname{col}(\phi_{fl}, \phi_{f\chi}).

Swapping lemma (exact with zero initial conditions: ``v - phi_fchi^T chi`` obeys
``(.)' = -a (.) - phi_fchi^T chi'``):

.. math:: \frac{a}{p + a}\bigl[\phi_\chi^\top \chi\bigr]
          = \phi_{f\chi}^\top \chi(t) - \frac{1}{p + a}\bigl[\phi_{f\chi}^\top \dot\chi\bigr] .

Replace ``chi' = Lambda chi + Psi theta_p + w`` (2) and ``chi = zeta + Omega theta_p + Phi e(0)``,
where the auxiliary filters (zero initial values, ``Phi(0) = I``)

.. math:: \dot\zeta = F \zeta + g, \qquad \dot\Omega = F \Omega + \Psi, \qquad \dot\Phi = F \Phi

are those of Statement 1 (``F = Lambda(y, u)``, ``g = w``; ``zeta = z``, ``Phi`` the
transition matrix ``Phi_Lambda``) or of Statement 2 (``F = Lambda_L = Lambda - L C``,
``g = w + L y``; ``zeta = z_1 + z_2``, ``Phi = exp(Lambda_L t)``).  In both cases the error
``e = chi - zeta - Omega theta_p`` obeys ``e' = F e`` (Statement 2 uses ``y = C chi``), so
``e(t) = Phi(t) e(0)`` with ``e(0) = chi(0)``.  The result is regression (4)/(5):

.. math::
    q_a := c_f + \frac{1}{p + a}\bigl[\phi_{f\chi}^\top (\Lambda \zeta + w)\bigr]
         = \psi_l^\top \theta_l + \psi_\chi^\top \chi(t) + \psi_e^\top e(0) + \psi_p^\top \theta_p,

.. math::
    \psi_l = \phi_{fl},\quad \psi_\chi = \phi_{f\chi},\quad
    \psi_e^\top = -\frac{1}{p + a}\bigl[\phi_{f\chi}^\top \Lambda \Phi\bigr],\quad
    \psi_p^\top = -\frac{1}{p + a}\bigl[\phi_{f\chi}^\top (\Lambda \Omega + \Psi)\bigr].

(``Lambda`` is the plant's in both statements; ``Lambda zeta + w`` and ``Lambda Omega + Psi``
are ``z'`` and ``Omega'`` of Statement 1.)  Every filter is a linear ODE driven by ``(y, u)``;
:meth:`Parametrization.derivative` returns all of them at once.

Extension (6) -- our reading.  The paper stacks ``N = l + 2 q + p`` copies with different
``a_i`` into a square ``Psi_e`` for the unknowns ``col(theta_l, chi(t), e(0), theta_p)``.
Those copies alone are singular whenever the coefficients ``phi_chi`` of (3) stay in a
proper subspace: for ``y = C chi`` with constant ``C`` every ``psi_chi = (1 - e^{-a t}) C^T``
is parallel, so for ``q >= 2`` ``det Psi_e = 0`` for all ``t`` -- the information on
``chi(t)`` reaches the regression only through ``e(0)``.  We therefore stack ``l + q + p``
filtered copies (distinct ``a_i``) and the ``q`` exact rows that define ``e(0)``,

.. math:: \chi(t) - \Phi(t)\, e(0) - \Omega(t)\, \theta_p = \zeta(t) ,

giving the same ``N x N`` regression ``Y_e = Psi_e col(theta_l, chi(t), e(0), theta_p)``
with the same unknowns; mixing, the estimator and the observer of Statement 3 are unchanged.
Every row is exact at every instant, so ``Y = adj(Psi_e) Y_e = Delta col(...)`` holds exactly
and ``Y_chi = Delta chi(t)``.
"""

from __future__ import annotations

import numpy as np

from obsfmu.observers.checks import ParameterError, as_vector

from .model import StateAffineModel, Terms

__all__ = ["Parametrization"]


class Parametrization:
    r"""Filters of Statements 1-2 and the extended regression ``Y_e = Psi_e col(theta_l, chi, e(0), theta_p)``.

    The filters are kept as three matrices in one flat state (one RK4 step advances all):

    * ``Z = [zeta | Omega | Phi]`` (``q x (1 + p + q)``), ``Z' = F Z + [g | Psi | 0]``;
    * ``G = [phi_f | c_f]`` (``k x (l + q + 1)``), ``G_i' = a_i ([phi^T, c] - G_i)``;
    * ``R = [-r | psi_p^T | psi_e^T]`` (``k x (1 + p + q)``),
      ``R_i' = -a_i R_i - phi_fchi,i^T (Lambda Z + [w | Psi | 0])``,

    so that ``q_a = c_f - R[:, 0]``, ``psi_p = R[:, 1:1+p]``, ``psi_e = R[:, 1+p:]``.

    Parameters
    ----------
    model : StateAffineModel
    rates : array_like
        ``k = l + q + p`` distinct filter rates ``a_i > 0`` of ``a_i / (p + a_i)``.

    Attributes
    ----------
    N : int
        ``l + 2 q + p``, the number of unknowns.
    theta_l, chi, e0, theta_p : slice
        Positions of the unknowns in ``col(theta_l, chi(t), e(0), theta_p)``.
    """

    def __init__(self, model: StateAffineModel, rates):
        self.model = model
        q, p, l = model.q, model.p, model.l
        self.k = k = l + q + p
        self.N = l + 2 * q + p
        rates = as_vector("rates", rates)
        if rates.size != k:
            raise ParameterError(f"rates: expected k = l + q + p = {k} filter rates a_i, got {rates.size}")
        if np.any(rates <= 0) or np.unique(rates).size != rates.size:
            raise ParameterError(f"rates: expected distinct a_i > 0, got {rates.tolist()}")
        self.rates = rates
        self.theta_l = slice(0, l)
        self.chi = slice(l, l + q)
        self.e0 = slice(l + q, l + 2 * q)
        self.theta_p = slice(l + 2 * q, self.N)
        width = 1 + p + q
        self._shapes = ((q, width), (k, l + q + 1), (k, width))     # Z, G, R
        self._sizes = np.cumsum([a * b for a, b in self._shapes])
        self._drive = np.zeros((q, width))                           # [w or g | Psi | 0]

    def _blocks(self, state: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        Z, G, R = np.split(state, self._sizes[:-1])
        return Z.reshape(self._shapes[0]), G.reshape(self._shapes[1]), R.reshape(self._shapes[2])

    def initial_state(self) -> np.ndarray:
        """Zero filters, ``Phi(0) = I``."""
        state = np.zeros(self._sizes[-1])
        Z = self._blocks(state)[0]
        Z[:, 1 + self.model.p:] = np.eye(self.model.q)
        return state

    def derivative(self, state: np.ndarray, terms: Terms, y: np.ndarray) -> np.ndarray:
        """Time derivative of every filter for the signals ``(y, u)`` whose model terms are ``terms``."""
        model, p, a = self.model, self.model.p, self.rates[:, None]
        Z, G, R = self._blocks(state)
        drive = self._drive.copy()
        drive[:, 1:1 + p] = terms.Psi
        drive[:, 0] = terms.w
        LZ = terms.Lambda @ Z
        z_dot = (model.Lambda_L @ Z if model.constant else LZ) + drive   # F Z + [g | Psi | 0]
        if model.constant:
            z_dot[:, 0] += model.L @ y                                     # g = w + L y (Statement 2)
        r_dot = -a * R - G[:, model.l:-1] @ (LZ + drive)                   # phi_fchi^T (Lambda Z + [w | Psi | 0])
        g_dot = a * (np.append(terms.phi, terms.c) - G)
        return np.concatenate((z_dot.ravel(), g_dot.ravel(), r_dot.ravel()))

    def regression(self, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(Y_e, Psi_e)``: ``k`` rows of (4)/(5), then the ``q`` rows defining ``e(0)``."""
        Z, G, R = self._blocks(state)
        q, p, l, k = self.model.q, self.model.p, self.model.l, self.k
        Psi_e = np.zeros((self.N, self.N))
        Y_e = np.empty(self.N)
        Psi_e[:k, :l + q] = G[:, :-1]               # psi_l = phi_fl, psi_chi = phi_fchi
        Psi_e[:k, self.e0] = R[:, 1 + p:]           # psi_e
        Psi_e[:k, self.theta_p] = R[:, 1:1 + p]     # psi_p
        Y_e[:k] = G[:, -1] - R[:, 0]                # q_a = c_f + r
        Psi_e[k:, self.chi] = np.eye(q)
        Psi_e[k:, self.e0] = -Z[:, 1 + p:]          # -Phi
        Psi_e[k:, self.theta_p] = -Z[:, 1:1 + p]    # -Omega
        Y_e[k:] = Z[:, 0]                           # zeta
        return Y_e, Psi_e
