r"""The DREM adaptive observer of paper 004 (Statements 1-3) as a :class:`~observers.block.Block`.

Three stages, all driven by the measured ``y`` and ``u``:

1. the filters of Statement 1 or 2 and the extended regression
   ``Y_e = Psi_e col(theta_l, chi(t), e(0), theta_p)``
   (:class:`~observers.state_affine.parametrization.Parametrization`);
2. mixing (7), ``Y = adj(Psi_e) Y_e = Delta col(theta_l, chi(t), e(0), theta_p)``, and the
   finite-time gradient estimator ("as in [5]") for the constant unknowns
   ``theta = col(theta_l, theta_p)``:

   .. math:: \dot{\hat\theta} = \gamma \Delta (Y_\theta - \Delta \hat\theta), \quad
             \dot\nu = -\gamma \Delta^2 \nu,\ \nu(0) = 1, \quad
             \theta^* = \frac{\hat\theta - \nu_c \hat\theta(0)}{1 - \nu_c},\ \nu_c = \min(\nu, \mu)

   (:func:`~observers.estimation.mix`, :func:`~observers.estimation.scalar_gradient_step`,
   :func:`~observers.estimation.finite_time_estimate`); ``theta*`` is exact once ``nu < mu``;
3. the observer of Statement 3,

   .. math:: \dot{\hat\chi} = \Lambda(y, u) \hat\chi + \Psi(y, u) \hat\theta_p + w(y, u)
             + \gamma_x \Delta (Y_\chi - \hat\chi \Delta), \qquad \hat x = \phi_L(\hat\chi, \hat\theta),

   whose error obeys ``chi_tilde' = (Lambda - gamma_x Delta^2 I) chi_tilde + Psi theta_tilde_p``
   because ``Y_chi = Delta chi(t)``: exponential convergence under condition (9).

Integration over a communication step ``h`` (in ``m = ceil(h / max_substep)`` sub-steps of
length ``dt``; ``y`` and ``u`` follow their :class:`~observers.block.Segment` lines):

* filters: one RK4 step (:func:`~observers.integrators.rk4_step`) per sub-step -- non-stiff;
* ``Delta`` and ``Y`` are taken linear between the sub-step ends, so the gradient law sees the
  exact averages ``<Delta^2>`` and ``<Delta Y>`` over the sub-step and is advanced exactly for
  them (:func:`scalar_gradient_step` with ``Delta_eff = sqrt<Delta^2>``); since
  ``Y_theta = Delta theta`` at both ends, ``theta_tilde`` is multiplied by
  ``exp(-gamma <Delta^2> dt)``, and ``nu`` by the same factor, so the finite-time identity
  ``theta_tilde = nu theta_tilde(0)`` holds to round-off for any gain;
* observer: the correction is ``gamma_x Delta^2 (chi_T - chi_hat)`` with the target
  ``chi_T = Y_chi / Delta = chi``; second-order exponential Runge-Kutta (ETD2RK, Cox & Matthews
  2002) with the stiff rate ``gamma_x <Delta^2>`` exact and ``chi_T`` linear over the sub-step,
  so that for ``gamma_x Delta^2 dt >> 1`` the step lands on ``chi`` at the sub-step's end (a
  target held over the step would lag by ``dt/2``).

The step is computed completely before the state is replaced, so a refused step
(:class:`~observers.checks.SignalError`) leaves the block unchanged.
"""

from __future__ import annotations

import math
from typing import Mapping, NamedTuple

import numpy as np

from obsfmu.observers.block import Block, Segment
from obsfmu.observers.checks import ParameterError, SignalError, as_vector, require_positive
from obsfmu.observers.estimation import finite_time_estimate, mix, phi1, scalar_gradient_step
from obsfmu.observers.integrators import require_budget, rk4_step, substep_count

from .model import StateAffineModel, Terms
from .parametrization import Parametrization

__all__ = ["StateAffineObserver", "SUBSTEP_BUDGET"]

#: default ``substep_budget``: an internal step costs about 1 ms, so a call takes a second at most
SUBSTEP_BUDGET = 1_000


class _Evolving(NamedTuple):
    """Everything one step changes (assigned to the block only once the step is complete)."""

    filters: np.ndarray
    mixed: np.ndarray     #: Y = adj(Psi_e) Y_e at the current time
    delta: float          #: Delta at the current time
    theta_drem: np.ndarray
    theta_hat: np.ndarray
    nu: float
    chi_hat: np.ndarray


def _phi2(x: float) -> float:
    r""":math:`\varphi_2(-x) = (e^{-x} - 1 + x) / x^2` for ``x >= 0`` (ETD2RK weight)."""
    if x < 1e-3:
        return 0.5 - x / 6.0 + x * x / 24.0 - x ** 3 / 120.0
    return (1.0 - phi1(x)) / x


class StateAffineObserver(Block):
    r"""Adaptive observer of paper 004 for a :class:`~observers.state_affine.model.StateAffineModel`.

    Parameters
    ----------
    model : StateAffineModel
        Maps, relation (3), left inverse; constant or time-varying ``Lambda``.
    rates : array_like
        ``l + q + p`` distinct filter rates ``a_i > 0`` (1/s).
    gamma : float
        Gain of the finite-time gradient estimator (1/s); ``gamma Delta^2`` is its rate.
    gamma_x : float
        Gain of the correction term of Statement 3 (1/s); ``gamma_x Delta^2`` is its rate.
    mu : float, default 0.98
        Switching level of the finite-time estimate, in (0, 1).
    chi_hat0 : array_like, optional
        Initial estimate of the image ``chi(0)`` (zeros by default).
    theta_hat0 : array_like, optional
        Initial estimate of ``col(theta_l, theta_p)`` (zeros by default).
    max_substep : float, optional
        Longest internal step (s); ``None``: one internal step per communication step.
    substep_budget : int, optional
        Most internal steps one communication step may take (a longer step is refused).
    converged_tolerance : float, default 1e-3
        ``converged`` is 1 once the guaranteed error of ``theta_hat`` is at most this.
    theta_bound : float, default 100
        A-priori bound on every entry of ``col(theta_l, theta_p)``.

    Attributes
    ----------
    theta_hat : ndarray
        Finite-time estimate ``theta*`` of ``col(theta_l, theta_p)``.
    chi_hat : ndarray
        Estimate of ``chi``.
    delta : float
        ``Delta`` (of the row-normalised ``Psi_e``) at the current time.
    nu : float
        ``nu``; ``theta*`` is exact once ``nu < mu``.
    switch_time : float or None
        First communication-step end with ``nu < mu``.
    converged : bool
        The diagnostics contract (docs/estimation.md, "Diagnostics"): ``nu < mu`` (``theta*`` exact
        for an exact regression) and ``nu max_i (|theta_hat0_i| + theta_bound) <= converged_tolerance``
        (the plain DREM estimate is within the tolerance too, so a small regression error, which
        ``theta*`` amplifies by ``1 / (1 - nu)``, is not amplified).  Output ``excitation = |Delta|``.
    """

    not_state = ("model", "parametrization", "gamma", "gamma_x", "mu", "max_substep", "substep_budget",
                 "theta_hat0", "converged_tolerance", "initial_error")
    state_optional = {"switch_time": None}

    def __init__(self, model: StateAffineModel, rates, gamma, gamma_x, mu=0.98, chi_hat0=None,
                 theta_hat0=None, max_substep=None, substep_budget=SUBSTEP_BUDGET, converged_tolerance=1e-3,
                 theta_bound=100.0):
        if not isinstance(model, StateAffineModel):
            raise ParameterError(f"model: expected a StateAffineModel, got {type(model).__name__}")
        self.model = model
        self.parametrization = Parametrization(model, rates)
        self.gamma = require_positive("gamma", gamma)
        self.gamma_x = require_positive("gamma_x", gamma_x)
        self.mu = require_positive("mu", mu)
        if self.mu >= 1.0:
            raise ParameterError(f"mu: must lie in (0, 1), got {self.mu:g}")
        q, n_theta = model.q, model.l + model.p
        self.max_substep = None if max_substep is None else require_positive("max_substep", max_substep)
        self.substep_budget = require_budget(substep_budget)
        self.theta_hat0 = np.zeros(n_theta) if theta_hat0 is None else as_vector("theta_hat0", theta_hat0, n_theta)
        chi_hat0 = np.zeros(q) if chi_hat0 is None else as_vector("chi_hat0", chi_hat0, q)
        self.converged_tolerance = require_positive("converged_tolerance", converged_tolerance)
        self.initial_error = float(np.max(np.abs(self.theta_hat0) + require_positive("theta_bound", theta_bound),
                                          initial=0.0))
        self.input_sizes = {"y": model.ny, "u": model.nu}
        self.output_sizes = {"x_hat": model.n, "theta_hat": n_theta, "chi_hat": q, "Delta": 1, "nu": 1,
                             "excitation": 1, "converged": 1}
        self.filters = self.parametrization.initial_state()
        self.mixed, self.delta = mix(*self.parametrization.regression(self.filters))
        self.theta_drem = self.theta_hat0.copy()
        self.theta_hat = self.theta_hat0.copy()
        self.nu = 1.0
        self.chi_hat = chi_hat0.copy()
        self.switch_time: float | None = None

    # ------------------------------------------------------------------ outputs
    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {"x_hat": self.model.inverse(self.chi_hat, self.theta_hat), "theta_hat": self.theta_hat.copy(),
                "chi_hat": self.chi_hat.copy(), "Delta": np.array([self.delta]), "nu": np.array([self.nu]),
                "excitation": np.array([abs(self.delta)]), "converged": np.array([float(self.converged)])}

    @property
    def converged(self) -> bool:
        return self.nu < self.mu and self.nu * self.initial_error <= self.converged_tolerance

    # ------------------------------------------------------------------ one step
    def _theta_part(self, mixed: np.ndarray) -> np.ndarray:
        P = self.parametrization
        return np.concatenate((mixed[P.theta_l], mixed[P.theta_p]))

    def _theta_p(self, theta: np.ndarray) -> np.ndarray:
        return theta[self.model.l:]

    @staticmethod
    def _targets(delta_0: float, Y_0: np.ndarray, delta_1: float, Y_1: np.ndarray, mean_d2: float,
                 mean_dY: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``Y_chi / Delta`` (``= chi``) at both sub-step ends; where ``Delta^2`` is below 1 % of the
        other end's, the ``Delta^2``-weighted mean ``<Delta Y_chi> / <Delta^2>`` instead (no division
        by a vanishing ``Delta``; the relaxation is weak there anyway)."""
        weighted = mean_dY / mean_d2
        floor = 1e-2 * max(delta_0 * delta_0, delta_1 * delta_1)
        ends = [Y / d if d * d >= floor and d != 0.0 else weighted for d, Y in ((delta_0, Y_0), (delta_1, Y_1))]
        return ends[0], ends[1]

    def _observer_step(self, chi: np.ndarray, dt: float, kappa: float, targets: tuple[np.ndarray, np.ndarray],
                       start: tuple[Terms, np.ndarray], end: tuple[Terms, np.ndarray]) -> np.ndarray:
        """ETD2RK step of ``chi' = -kappa (chi - chi_T(s)) + Lambda chi + Psi theta_p + w`` (Statement 3).

        ``gamma_x Delta (Y_chi - Delta chi) = gamma_x Delta^2 (chi_T - chi)`` with the target
        ``chi_T = Y_chi / Delta`` (the true ``chi``); ``kappa = gamma_x <Delta^2>`` over the sub-step
        and ``chi_T`` linear between its ends.  ETD2RK is exact for a forcing linear in time, so
        for ``kappa dt >> 1`` the step lands on ``chi_T`` at the end of the sub-step.
        """
        def right_side(terms: Terms, theta_p: np.ndarray, target: np.ndarray, value: np.ndarray) -> np.ndarray:
            return terms.Lambda @ value + terms.Psi @ theta_p + terms.w + kappa * target
        x = kappa * dt
        n0 = right_side(*start, targets[0], chi)
        predictor = math.exp(-x) * chi + dt * phi1(x) * n0
        n1 = right_side(*end, targets[1], predictor)
        return predictor + dt * _phi2(x) * (n1 - n0)

    def _substep(self, state: _Evolving, dt: float, s0: float, signals, derivative) -> _Evolving:
        """One internal step ``[s0, s0 + dt]``: filters (RK4), mixing, FT gradient, Statement 3."""
        P = self.parametrization
        s1 = s0 + dt                          # the same float rk4_step uses: the signal cache hits
        filters = rk4_step(derivative, s0, state.filters, dt)
        mixed, delta = mix(*P.regression(filters))
        d0, Y0 = state.delta, state.mixed
        # exact averages of Delta^2 and Delta Y for Delta, Y linear over the sub-step
        mean_d2 = (d0 * d0 + d0 * delta + delta * delta) / 3.0
        mean_dY = ((2.0 * d0 + delta) * Y0 + (d0 + 2.0 * delta) * mixed) / 6.0
        theta_drem, chi, targets = state.theta_drem, state.chi_hat, (state.chi_hat, state.chi_hat)
        if mean_d2 > 0.0:
            delta_eff = math.sqrt(mean_d2)
            theta_drem = scalar_gradient_step(theta_drem, self._theta_part(mean_dY) / delta_eff, delta_eff,
                                              self.gamma, dt)
            targets = self._targets(d0, Y0[P.chi], delta, mixed[P.chi], mean_d2, mean_dY[P.chi])
        nu = state.nu * math.exp(-self.gamma * mean_d2 * dt)
        theta_hat = finite_time_estimate(theta_drem, self.theta_hat0, nu, self.mu)
        chi = self._observer_step(chi, dt, self.gamma_x * mean_d2, targets,
                                  (signals(s0)[0], self._theta_p(state.theta_hat)),
                                  (signals(s1)[0], self._theta_p(theta_hat)))
        return _Evolving(filters, mixed, delta, theta_drem, theta_hat, nu, chi)

    def advance(self, t: float, h: float, inputs: Mapping[str, Segment]) -> None:
        y_line, u_line = inputs["y"], inputs["u"]
        steps = 1 if self.max_substep is None else substep_count(h, self.max_substep, budget=self.substep_budget)
        dt = h / steps
        cache: dict[float, tuple[Terms, np.ndarray]] = {}

        def signals(s: float) -> tuple[Terms, np.ndarray]:
            """Model terms and ``y`` at ``t + s`` along the input lines (each time evaluated once)."""
            if s not in cache:
                y = np.asarray(y_line.at(s), dtype=float).reshape(self.model.ny)
                u = np.asarray(u_line.at(s), dtype=float).reshape(self.model.nu)
                cache[s] = (self.model.evaluate(y, u), y)
            return cache[s]

        def derivative(s: float, filters: np.ndarray) -> np.ndarray:
            terms, y = signals(s)
            return self.parametrization.derivative(filters, terms, y)

        state = _Evolving(self.filters, self.mixed, self.delta, self.theta_drem, self.theta_hat, self.nu,
                          self.chi_hat)
        s0 = 0.0
        for _ in range(steps):
            state = self._substep(state, dt, s0, signals, derivative)
            s0 += dt
        if not all(np.all(np.isfinite(v)) for v in (state.filters, state.chi_hat, state.theta_hat)):
            raise SignalError(f"state: the step from t = {t:g} would make the observer state non-finite "
                              "(filters growing? check Assumption 4 / the eigenvalues of Lambda - L C); "
                              "state unchanged")
        if self.switch_time is None and state.nu < self.mu:
            self.switch_time = t + h
        (self.filters, self.mixed, self.delta, self.theta_drem, self.theta_hat, self.nu,
         self.chi_hat) = state
