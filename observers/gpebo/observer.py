r"""Discrete adaptive observer of paper 000 (GPEBO + DREM), as a block.

The observer processes sample ``k`` at the instant ``t_k = k Ts`` (any communication step:
:class:`~observers.sampling.SampledBlock`) from ``u(k)``, ``y(k)``, the inputs at ``t_k``:

1. *Generator coefficients.*  Row ``(zeta(k), rho(k))`` of the input-output
   regression (16) (:func:`~observers.gpebo.regression.regression_for`: the example's own
   derivation for its structure, the determinant regression of any other plant of the class),
   :class:`~observers.estimation.DiscreteDREM` with delays ``1 .. p - 1``
   (18)-(19), row-normalised, and the update of Statement 2; then
   ``gamma_hat = sigma^L(sigma_hat)`` (stage 1).
2. *Generator initial states.*  If ``gamma_hat`` moved by more than
   ``restart_tol`` since the filters were started, restart them
   (:class:`~observers.gpebo.filters.GpeboFilters`) at this sample with the
   new ``Gamma_hat``, warm-starting ``eta_hat`` with the current ``xi_hat``.
   Once the filters are ``n`` samples old, ``y(k) = phi_y(k) eta`` is exact
   and feeds a second DiscreteDREM (delays ``1 .. N-1``) for ``eta = xi(t0)``.
3. *State.*  The filters advance with ``u(k)``, ``y(k)``; the outputs at
   ``k + 1`` are ``x_hat(k+1) = phi_x(k+1) eta_hat + e_hat(k+1)`` (3) and
   ``xi_hat(k+1) = Phi(k+1) eta_hat`` -> ``beta_hat``, ``theta_hat``: a
   one-sample prediction from ``y(0 .. k)``, so the block has no direct
   feedthrough.

Excitation certificate.  With an exact regression Statement 2 gives
``sigma_tilde(k) = nu_gamma(k) sigma_tilde(0)``,
``nu_gamma = prod_j k_gamma / (k_gamma + Delta_j^2)``; the same for ``eta``
since the last restart (``nu_eta``).  ``excited = 1`` when both are below
``excitation_tol``: the estimates are then determined by the data, whatever
the initial guesses were.  ``excited = 0`` says the regressions have not
been exciting (e.g. a constant input): the estimates are not to be trusted.

Diagnostics contract (docs/estimation.md, "Diagnostics").  With ``|sigma_i| <= theta_bound``
and ``|eta_i| <= theta_bound`` a priori, ``|sigma_hat_i - sigma_i| <= nu_gamma (|sigma_hat_i(0)|
+ theta_bound)`` and ``|eta_hat_i - eta_i| <= nu_eta (|eta_hat_i(t_r)| + theta_bound)`` (``t_r``
the last restart); through ``gamma = sigma^L(sigma)`` (the regression's ``error_bound``) the
first bounds ``|gamma_hat - gamma|``.  ``converged = 1`` when both are at most ``converged_tolerance`` and the
filters run with a ``Gamma`` within that tolerance of the true one (the eta regression is exact
only then: the assumption is that an error below the tolerance there leaves eta's bound valid);
``excitation = min(|Delta_sigma|, |Delta_eta|)`` at the last sample.  The bounds hold for an exact
regression only, so ``converged`` also needs the data to be consistent with the estimate: the
a-priori relative residuals of the last ``p`` rows of the gamma regression (16),
``|zeta - rho^T sigma_hat(k-1)| / |(zeta, rho)|``, at most ``consistency_tol`` (round-off gives
~1e-15; measurement noise or a plant outside the model gives more, and the flag stays 0).  The eta
regression is not tested this way: its rows can be small, and its round-off residual reaches
~1e-10 relative on exact data.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from obsfmu.observers.checks import ParameterError, as_vector, finite_signal, require_positive
from obsfmu.observers.estimation import DelayExtension, DiscreteDREM

from ..sampling import SampledBlock
from .filters import GpeboFilters
from .model import GeneratorModel
from .regression import regression_for

__all__ = ["GpeboObserver"]

#: the gamma DREM's round-off floor (:class:`~observers.estimation.DiscreteDREM`): k' = max(k_gamma, 1e-8
#: Delta_max^2), so a sample whose ``Delta^2`` is far below 1e-8 of the best one seen barely moves sigma_hat
#: (without it, a full-gamma regression of p = 47 on exact data jumped from 4e-15 to 8.8e-12 at a sample with
#: Delta = 3e-14; with it 1.1e-13 at worst).  |Delta| <= 1 (rows normalised), so for k_gamma >= 1e-8 (the
#: default, the paper's example) the law is Statement 2 exactly
RELATIVE_FLOOR = 1e-8


def _residual(z: float, row: np.ndarray, estimate: np.ndarray) -> float:
    """A-priori relative residual ``|z - row^T estimate| / |(z, row)|`` of a new regression row."""
    scale = float(np.sqrt(z * z + row @ row))
    return abs(z - float(row @ estimate)) / scale if scale > 0 else 0.0


class GpeboObserver(SampledBlock):
    r"""Adaptive observer of paper 000 for a plant of its class: ``gamma``, ``eta = xi(t0)`` and ``x``.

    Parameters
    ----------
    model : GeneratorModel
        The known structure (``n``, ``h_beta``, ``H_theta``, ``H_delta``, ``f``); by default every
        generator is ``gamma_• = [0, ..., 0, g_•]`` with ``g_•`` unknown, else see ``gamma_unknown``
        (:func:`~observers.gpebo.regression.regression_for`).
    Ts : float
        Sample period (s): the only communication step accepted.
    k_gamma, k_eta : float
        Gains ``k_i > 0`` of Statement 2 for the two DREMs (rows are
        normalised, so ``Delta^2 <= 1``; small ``k`` is fast: the error
        shrinks by ``1 + Delta^2 / k`` per sample).
    gamma_hat0 : array_like, shape (number of unknowns,)
        Initial ``[g_beta, g_theta(, g_delta)]`` (or the entries ``regression.names``); the ones the
        regression divides by nonzero.
    eta_hat0 : array_like, shape (N,), optional
        Initial ``xi_hat(0)`` (zeros by default).
    x_hat0 : array_like, shape (n,), optional
        Initial state estimate (zeros by default).
    restart_tol : float
        Relative change of ``gamma_hat`` that restarts the filters.
    excitation_tol : float
        Threshold on ``nu_gamma`` and ``nu_eta`` for ``excited``.
    converged_tolerance, theta_bound : float
        The ``converged`` criterion (module docstring).
    consistency_tol : float
        Largest a-priori relative residual of the last ``p`` gamma rows for ``converged`` (exact data only).
    gamma_unknown : sequence of "last" | "all", optional
        Per generator (beta, theta, delta) which entries of ``gamma`` are unknown: "last" (default)
        ``gamma = [0, ..., 0, g]``, "all" the whole vector (:mod:`~observers.gpebo.companion`; then
        ``gamma_hat0`` has one entry per unknown, in the order of ``regression.names``).

    Ports: inputs ``u``, ``y``; outputs ``x_hat`` (n), ``gamma_hat`` (number of generators),
    ``eta_hat`` (N), ``beta_hat``, ``theta_hat`` (n), ``excited``,
    ``nu_gamma``, ``nu_eta``, ``restart_time``.
    """

    not_state = ("model", "regression", "Ts", "k_gamma", "k_eta", "restart_tol", "excitation_tol",
                 "converged_tolerance", "theta_bound", "consistency_tol", "sigma_error0")

    def __init__(self, model: GeneratorModel, Ts: float, k_gamma: float = 1e-8, k_eta: float = 1e-8,
                 gamma_hat0=(-0.5, 0.5), eta_hat0=None, x_hat0=None, restart_tol: float = 1e-11,
                 excitation_tol: float = 1e-9, converged_tolerance: float = 1e-6, theta_bound: float = 100.0,
                 consistency_tol: float = 1e-10, gamma_unknown=None):
        self.model = model
        self.regression = regression_for(model, gamma_unknown)
        self.Ts = require_positive("Ts", Ts)
        self.k_gamma = require_positive("k_gamma", k_gamma)
        self.k_eta = require_positive("k_eta", k_eta)
        self.restart_tol = require_positive("restart_tol", restart_tol)
        self.excitation_tol = require_positive("excitation_tol", excitation_tol)
        self.converged_tolerance = require_positive("converged_tolerance", converged_tolerance)
        self.theta_bound = require_positive("theta_bound", theta_bound)
        self.consistency_tol = require_positive("consistency_tol", consistency_tol)
        names = self.regression.names
        gamma_hat0 = as_vector("gamma_hat0", gamma_hat0, len(names))
        for v in self.regression.divisors:
            if gamma_hat0[v] == 0:
                raise ParameterError(f"gamma_hat0: {names[v]} (entry {v + 1}) must be nonzero; the regression is "
                                     f"divided by it (the paper assumes {names[v]} != 0)")
        N, n = model.N, model.n
        eta_hat0 = np.zeros(N) if eta_hat0 is None else as_vector("eta_hat0", eta_hat0, N)
        x_hat0 = np.zeros(n) if x_hat0 is None else as_vector("x_hat0", x_hat0, n)

        p = self.regression.p
        self.gamma_drem = DiscreteDREM(DelayExtension(range(1, p)), self.k_gamma,
                                       theta0=self.regression.sigma(*gamma_hat0), relative_floor=RELATIVE_FLOOR)
        self.eta_drem = DiscreteDREM(DelayExtension(range(1, N)), self.k_eta, theta0=eta_hat0)
        self.sigma_error0 = np.abs(self.gamma_drem.theta_hat) + self.theta_bound   #: bounds |sigma_tilde(0)|
        self.eta_start = eta_hat0.copy()                                           #: eta_hat at the last restart
        self.filter_gammas = gamma_hat0
        self.filters = GpeboFilters(model, self._transition(gamma_hat0), x_hat0)
        self.window = np.zeros((self.regression.window, 2))  #: [u, y] of samples k-6 .. k, oldest first
        self.samples = 0
        self.nu_gamma = 1.0
        self.nu_eta = 1.0
        self.restart_time = 0.0
        self.residuals = np.ones(p)   #: a-priori relative residuals of the last p rows of the gamma regression
        self.input_sizes = {"u": 1, "y": 1}
        self._init_sampling(self.input_sizes)
        self.output_sizes = {"x_hat": n, "gamma_hat": len(names), "eta_hat": N, "beta_hat": 1, "theta_hat": n,
                             "excited": 1, "nu_gamma": 1, "nu_eta": 1, "restart_time": 1,
                             "excitation": 1, "converged": 1}

    # ------------------------------------------------------------------ pieces
    def _transition(self, gammas) -> np.ndarray:
        return self.model.transition(*self.regression.full_coefficients(gammas))

    @property
    def gamma_hat(self) -> np.ndarray:
        """``[g_beta_hat, g_theta_hat(, g_delta_hat)] = sigma^L(sigma_hat)``."""
        return self.regression.gammas(self.gamma_drem.theta_hat)

    @property
    def excited(self) -> bool:
        return self.nu_gamma < self.excitation_tol and self.nu_eta < self.excitation_tol

    def gamma_error_bound(self) -> float:
        """Guaranteed bound on ``max |gamma_hat - gamma|`` (Statement 2 and ``gamma = sigma^L(sigma)``)."""
        return self.regression.error_bound(self.gamma_drem.theta_hat, self.nu_gamma * self.sigma_error0)

    def eta_error_bound(self) -> float:
        """Bound on ``max |eta_hat - eta|`` since the last restart (exact eta regression)."""
        return float(self.nu_eta * np.max(np.abs(self.eta_start) + self.theta_bound))

    @property
    def converged(self) -> bool:
        """Both bounds within the tolerance, and the filters run with a ``Gamma`` within it of the true one
        (``|gamma_filters - gamma| <= |gamma_filters - gamma_hat| + bound``): the eta regression is
        exact only for the true ``Gamma``."""
        tolerance, bound = self.converged_tolerance, self.gamma_error_bound()
        gap = float(np.max(np.abs(self.filter_gammas - self.gamma_hat))) + bound
        return (bound <= tolerance and gap <= tolerance and self.eta_error_bound() <= tolerance
                and float(np.max(self.residuals)) <= self.consistency_tol)

    def _moved(self, gammas: np.ndarray) -> bool:
        scale = max(1.0, float(np.max(np.abs(gammas))))
        return float(np.max(np.abs(gammas - self.filter_gammas))) > self.restart_tol * scale

    # ------------------------------------------------------------------ Block
    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        eta_hat = self.eta_drem.theta_hat
        beta, theta, _ = self.model.coefficients(self.filters.generator_estimate(eta_hat))
        return {"x_hat": self.filters.state_estimate(eta_hat), "gamma_hat": self.gamma_hat,
                "eta_hat": eta_hat.copy(), "beta_hat": np.array([beta]), "theta_hat": theta,
                "excited": np.array([float(self.excited)]), "nu_gamma": np.array([self.nu_gamma]),
                "nu_eta": np.array([self.nu_eta]), "restart_time": np.array([self.restart_time]),
                "excitation": np.array([min(abs(self.gamma_drem.delta), abs(self.eta_drem.delta))]),
                "converged": np.array([float(self.converged)])}

    def sample_period(self) -> float:
        return self.Ts

    def sample(self, t_k: float, inputs: Mapping[str, np.ndarray]) -> None:
        """Process sample ``k`` (``u(k)``, ``y(k)``: the inputs latched at ``t_k``)."""
        u = float(finite_signal("u", inputs["u"])[0])
        y = float(finite_signal("y", inputs["y"])[0])
        self.model.nonlinearity(y)  # a bad f(y) is refused before anything changes
        saved = self.get_state()
        try:
            self._sample(t_k, u, y)
        except Exception:
            self.set_state(saved, check=False)
            raise

    def _sample(self, t: float, u: float, y: float) -> None:
        # step 1: gamma from the input-output regression (16), DREM (18)-(19), Statement 2
        self.window = np.vstack([self.window[1:], [u, y]])
        self.samples += 1
        if self.samples >= self.regression.window:
            zeta, rho = self.regression.row(self.window[:, 0], self.window[:, 1])
            self.residuals = np.append(self.residuals[1:], _residual(zeta, rho, self.gamma_drem.theta_hat))
            self.gamma_drem.update(zeta, rho)
            self.nu_gamma *= float(np.max(self.gamma_drem.contraction))
        gammas = self.gamma_hat
        if self._moved(gammas):
            eta_hat = self.eta_drem.theta_hat
            xi_hat, x_hat = self.filters.generator_estimate(eta_hat), self.filters.state_estimate(eta_hat)
            self.filters.restart(self._transition(gammas), x_hat)
            self.eta_drem.reset(xi_hat)
            self.eta_start = xi_hat.copy()
            self.filter_gammas, self.nu_eta, self.restart_time = gammas, 1.0, t
        # step 2: eta = xi(t0) from y = phi_y eta (4), DREM with delays (17)-(19)
        if self.filters.exact:
            self.eta_drem.update(y, self.filters.phi_y)
            self.nu_eta *= self.k_eta / (self.k_eta + self.eta_drem.delta ** 2)
        # step 3: the filters (hence x_hat = phi_x eta_hat + e_hat) move to sample k + 1
        self.filters.advance(u, y)
