r"""Example plants for paper 004 (the paper has none) and their maps to the state-affine form.

Each plant is a :class:`~observers.block.Block` (the plant FMU) and comes with the functions a
user of :class:`~observers.state_affine.StateAffineModel` writes: ``Psi``, ``w``, ``phi``,
``c``, ``phi_L`` (and ``Lambda`` when it is not constant).  Inside an FMU they are referenced
as ``"plants.state_affine:<name>"``.  Known constants of the models live here once and are
shared by the plant and its model.

Pendulum (Statement 2, constant ``Lambda``)
    Damped pendulum driven by a torque, measured in angle only (Khalil, *Nonlinear Systems*,
    3rd ed., 2002, Sec. 1.2.1), with unknown gravity *and* friction coefficients:

    .. math:: \dot\varphi = \omega, \qquad \dot\omega = -a \sin\varphi - b\,\omega + u,
              \qquad y = \varphi,

    ``a = g / l`` (1/s^2), ``b`` the viscous friction coefficient (1/s), ``u`` the torque
    divided by ``m l^2`` (rad/s^2).  The friction term multiplies the unmeasured ``omega``;
    the filtered transformation ``chi = (varphi, omega + b varphi)`` (adaptive observer form,
    Marino & Tomei, *Nonlinear Control Design*, 1995) removes it:

    .. math:: \dot\chi = \begin{bmatrix} 0 & 1 \\ 0 & 0 \end{bmatrix} \chi
              + \begin{bmatrix} -y & 0 \\ 0 & -\sin y \end{bmatrix}
                \begin{bmatrix} b \\ a \end{bmatrix} + \begin{bmatrix} 0 \\ u \end{bmatrix},
              \qquad y = \chi_1 ,

    so ``q = 2``, ``p = 2`` (``theta_p = (b, a)``), ``l = 0``, relation (3) is ``chi_1 = y``
    and ``x = phi_L(chi, theta) = (chi_1, chi_2 - b chi_1)`` (the map depends on ``b``).

Chemostat (Statement 1, time-varying ``Lambda(y, u)``)
    Continuous bioreactor with one biomass growing on one substrate, Monod kinetics (Bastin &
    Dochain, *On-line Estimation and Adaptive Control of Bioreactors*, Elsevier, 1990; Smith &
    Waltman, *The Theory of the Chemostat*, 1995) -- the class of chemical-biological reactors
    for which GPEBO was developed (Ortega, Bobtsov, Nikolaev, Schiffer, Dochain, Automatica
    129 (2021) 109635, reference [4] of paper 004):

    .. math:: \dot X = \mu(S) X - D X, \qquad \dot S = -k\,\mu(S) X + D (S_{in} - S), \qquad
              \mu(S) = \frac{\mu_m S}{K_S + S},

    measured substrate ``y = S``, input the dilution rate ``u = D`` (1/h), unknown biomass
    ``X`` and unknown feed concentration ``S_in``; ``mu_m``, ``K_S`` and the yield
    coefficient ``k`` are known.  With ``chi = x = (X, S)``:

    .. math:: \Lambda(y, u) = \begin{bmatrix} \mu(y) - u & 0 \\ -k \mu(y) & -u \end{bmatrix}, \quad
              \Psi(y, u) = \begin{bmatrix} 0 \\ u \end{bmatrix}, \quad w = 0, \quad \chi_2 = y,

    so ``q = 2``, ``p = 1`` (``theta_p = S_in``), ``l = 0``, ``phi_L`` the identity.  Time is
    in hours.
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from obsfmu.observers.block import Block, Segment
from obsfmu.observers.checks import ParameterError, SignalError, as_vector, require_positive
from obsfmu.observers.integrators import DEFAULT_SUBSTEP_BUDGET, require_budget, substep_count

__all__ = [
    "Pendulum", "Chemostat",
    "PENDULUM_LAMBDA", "PENDULUM_C", "pendulum_Psi", "pendulum_w", "pendulum_phi", "pendulum_c",
    "pendulum_phi_L",
    "CHEMOSTAT_MU_MAX", "CHEMOSTAT_K_S", "CHEMOSTAT_YIELD", "monod", "chemostat_Lambda", "chemostat_Psi",
    "chemostat_w", "chemostat_phi", "chemostat_c", "chemostat_phi_L",
]


class _OdePlant(Block):
    """A plant ``x' = f(x, u)``, ``y = x[output_index]``, advanced by RK4 sub-steps along the input line.

    Outputs ``y``, the true state ``x`` and the true unknown parameters ``theta`` (constant, for
    comparison with an observer's estimate).
    """

    output_index: int = 0
    not_state = ("max_substep", "substep_budget")

    def __init__(self, x0, max_substep: float, substep_budget: int = DEFAULT_SUBSTEP_BUDGET):
        self.x = as_vector("x0", x0, 2)
        self.max_substep = max_substep
        self.substep_budget = require_budget(substep_budget)
        self.input_sizes = {"u": 1}
        self.output_sizes = {"y": 1, "x": self.x.size, "theta": self.theta.size}

    @property
    def theta(self) -> np.ndarray:
        """The parameters unknown to the observer, in the order of its ``theta_hat``."""
        raise NotImplementedError

    def rhs(self, x: np.ndarray, u: float) -> np.ndarray:
        raise NotImplementedError

    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {"y": self.x[self.output_index:self.output_index + 1].copy(), "x": self.x.copy(),
                "theta": self.theta}

    def advance(self, t: float, h: float, inputs: Mapping[str, Segment]) -> None:
        u = inputs["u"]
        steps = substep_count(h, self.max_substep, budget=self.substep_budget)
        dt = h / steps
        x = self.x
        for i in range(steps):
            s = i * dt
            k1 = self.rhs(x, float(u.at(s)[0]))
            k2 = self.rhs(x + dt / 2 * k1, float(u.at(s + dt / 2)[0]))
            k3 = self.rhs(x + dt / 2 * k2, float(u.at(s + dt / 2)[0]))
            k4 = self.rhs(x + dt * k3, float(u.at(s + dt)[0]))
            x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        if not np.all(np.isfinite(x)):
            raise SignalError(f"x: the step from t = {t:g} makes the plant state non-finite; state unchanged")
        self.x = x


# ---------------------------------------------------------------------------- pendulum
#: constant matrices of the pendulum's state-affine form: chi' = Lambda chi + ..., y = C chi
PENDULUM_LAMBDA = np.array([[0.0, 1.0], [0.0, 0.0]])
PENDULUM_C = np.array([[1.0, 0.0]])


class Pendulum(_OdePlant):
    r"""``phi' = omega``, ``omega' = -a sin(phi) - b omega + u``, ``y = phi``; state ``x = (phi, omega)``.

    Parameters
    ----------
    a : float
        Gravity coefficient ``g / l`` (1/s^2).
    b : float
        Viscous friction coefficient (1/s), ``>= 0``.
    x0 : array_like
        ``(phi(0), omega(0))`` (rad, rad/s).
    max_substep : float
        Longest RK4 step (s).
    substep_budget : int
        Most RK4 steps one communication step may take (a longer step is refused).
    """

    not_state = ("a", "b")

    def __init__(self, a, b, x0, max_substep: float = 1e-3, substep_budget: int = DEFAULT_SUBSTEP_BUDGET):
        self.a = float(as_vector("a", a, 1)[0])
        self.b = require_positive("b", b, allow_zero=True)
        super().__init__(x0, require_positive("max_substep", max_substep), substep_budget)

    @property
    def theta(self) -> np.ndarray:
        """``theta_p = (b, a)``."""
        return np.array([self.b, self.a])

    def rhs(self, x: np.ndarray, u: float) -> np.ndarray:
        return np.array([x[1], -self.a * math.sin(x[0]) - self.b * x[1] + u])


def pendulum_Psi(y, u):
    """``Psi(y, u)`` of the pendulum: ``theta_p = (b, a)``."""
    return np.array([[-y[0], 0.0], [0.0, -math.sin(y[0])]])


def pendulum_w(y, u):
    return np.array([0.0, u[0]])


def pendulum_phi(y, u):
    """Relation (3) ``chi_1 = y``: ``phi_chi = (1, 0)`` (no ``theta_l``)."""
    return np.array([1.0, 0.0])


def pendulum_c(y, u):
    return y[0]


def pendulum_phi_L(chi, theta):
    """``x = (chi_1, chi_2 - b chi_1)`` with ``b = theta[0]``."""
    return np.array([chi[0], chi[1] - theta[0] * chi[0]])


# ---------------------------------------------------------------------------- chemostat
CHEMOSTAT_MU_MAX = 0.5  #: maximal specific growth rate mu_m (1/h)
CHEMOSTAT_K_S = 1.0     #: half-saturation constant K_S (g/L)
CHEMOSTAT_YIELD = 2.0   #: yield coefficient k (g substrate per g biomass)


def monod(S: float) -> float:
    """Specific growth rate ``mu(S) = mu_m S / (K_S + S)`` (1/h)."""
    return CHEMOSTAT_MU_MAX * S / (CHEMOSTAT_K_S + S)


class Chemostat(_OdePlant):
    r"""``X' = mu(S) X - D X``, ``S' = -k mu(S) X + D (S_in - S)``, ``y = S``, ``u = D``; ``x = (X, S)``.

    Parameters
    ----------
    S_in : float
        Substrate concentration of the feed (g/L), ``> 0``.
    x0 : array_like
        ``(X(0), S(0))`` (g/L), non-negative.
    max_substep : float
        Longest RK4 step (h).
    substep_budget : int
        Most RK4 steps one communication step may take (a longer step is refused).
    """

    output_index = 1
    not_state = ("S_in",)

    def __init__(self, S_in, x0, max_substep: float = 0.01, substep_budget: int = DEFAULT_SUBSTEP_BUDGET):
        self.S_in = require_positive("S_in", S_in)
        super().__init__(x0, require_positive("max_substep", max_substep), substep_budget)
        if np.any(self.x < 0):
            raise ParameterError(f"x0: concentrations must be >= 0, got {self.x.tolist()}")

    @property
    def theta(self) -> np.ndarray:
        """``theta_p = S_in``."""
        return np.array([self.S_in])

    def rhs(self, x: np.ndarray, u: float) -> np.ndarray:
        growth = monod(x[1]) * x[0]
        return np.array([growth - u * x[0], -CHEMOSTAT_YIELD * growth + u * (self.S_in - x[1])])


def chemostat_Lambda(y, u):
    """``Lambda(y, u)`` of the chemostat (Statement 1: time-varying)."""
    mu = monod(y[0])
    return np.array([[mu - u[0], 0.0], [-CHEMOSTAT_YIELD * mu, -u[0]]])


def chemostat_Psi(y, u):
    """``Psi(y, u) = (0, D)``: ``theta_p = S_in``."""
    return np.array([[0.0], [u[0]]])


def chemostat_w(y, u):
    return np.zeros(2)


def chemostat_phi(y, u):
    """Relation (3) ``chi_2 = y``: ``phi_chi = (0, 1)``."""
    return np.array([0.0, 1.0])


def chemostat_c(y, u):
    return y[0]


def chemostat_phi_L(chi, theta):
    return np.array(chi, dtype=float)
