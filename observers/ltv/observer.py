r"""Adaptive observer for a nonlinear LTV plant with unknown constant parameters (paper 001).

Kozachek, Bobtsov, Nikolaev (2023).  Plant (1), with ``A(t)``, ``C(t)``, ``f_i`` known and
``k``, ``b``, ``m_i``, ``x(0)`` unknown (the paper's ``w(y, t) = m f(y)`` is ``p = 1``):

.. math:: \dot x = A(t) x + k C^T(t) x + b u + \sum_{i=1}^{p} m_i f_i(y, t), \qquad y = C^T(t) x .

With ``L(t)`` such that ``A0(t) = A(t) - L(t) C^T(t)`` is uniformly stable, the filters
(2)-(6), all zero at ``t = 0`` except ``Phi(0) = I``,

.. math::
    \dot\xi = A_0 \xi + L y, \quad \dot\eta = A_0 \eta + I y, \quad \dot\zeta = A_0 \zeta + I u,
    \quad \dot\rho_i = A_0 \rho_i + I f_i(y, t), \quad \dot\Phi = A_0 \Phi,

give an exact identity: the error (8) ``e = xi + eta k + zeta b + sum_i rho_i m_i - x`` obeys
``e' = A0 e`` (``k C^T x = k y``), so (9) ``e = Phi theta`` with ``theta = e(0) = -x(0)``, and (10) reads

.. math:: x = \xi + W \Theta, \qquad W = [-\Phi,\ \eta,\ \zeta,\ \rho_1, \dots, \rho_p], \qquad
          \Theta = [\theta;\ k;\ b;\ m_1; \dots; m_p],

hence the linear regression (7)

.. math:: z = y - C^T(t) \xi = \Psi \Theta, \qquad \Psi = C^T(t) W,

estimated by least squares with forgetting and a bound on ``F`` (the unnumbered law after (10);
:class:`~observers.estimation.LeastSquaresForgetting`, ``lambda_max(F) <= M`` read as the paper's
``F <= M``), and the state estimate from (10)

.. math:: \hat x = \xi - \Phi \hat\theta + \eta \hat k + \zeta \hat b + \sum_i \rho_i \hat m_i = \xi + W \hat\Theta .

Integration over a communication step
-------------------------------------
* Inputs: ``y`` and ``u`` arrive as :class:`~observers.block.Segment` s; inside the step they
  follow the polynomial of degree ``input_degree`` through the last communication points when
  the master interpolates (:class:`~observers.ltv.stepping.PolynomialInputs`), the segments
  themselves otherwise.
* Filters: one linear ODE ``S' = A0(t) S + G(t)`` for ``S = [xi, W]`` (we store ``-Phi``, which
  obeys the same equation from ``-I``), RK4 sub-steps at most ``max_substep`` long over which
  ``y`` changes by at most ``max_dy`` (``f(y)`` must be resolved: with ``f = sin`` and ``|y|`` in
  the thousands, ``y`` moves by radians per millisecond).
* Estimator: in its information form the least-squares law adds
  ``gamma int exp(-beta (h - s)) Psi^T Psi ds`` to ``P`` over a step (and the same with
  ``Psi^T z`` to ``q``).  Each sub-step contributes the regression at its two Gauss-Legendre nodes
  (RK4's third-order dense output gives ``S`` there), each row scaled by the square root of its
  quadrature weight times its forgetting factor, and the whole step's rows go to the estimator as
  ONE held regression over the step: Gauss quadrature of the weighted integrals, fourth order
  (:func:`_quadrature_weights`).  The midpoint rule instead costs 3e-4 in ``Theta_hat`` during
  the first 0.1 s of the bounded example at h = 1e-3 (Gauss: 7e-7), equal weights ``O(beta h)``.

``C`` and the nonlinearities are :mod:`observers.ltv.model`'s: a constant ``C`` (the paper's example)
or ``C(t)``, and ``p >= 1`` nonlinearities ``f_i`` (one function returning ``p`` values).
"""

from __future__ import annotations

import copy
from functools import lru_cache
from typing import Mapping

import numpy as np

from ..block import Block, Segment
from ..checks import ParameterError, as_vector, finite_signal, require_positive
from ..estimation.exponential import phi1
from ..integrators import DEFAULT_SUBSTEP_BUDGET, require_budget, substep_count
from .assumptions import require_assumptions
from .estimators import DELTA_FLOOR, ESTIMATORS, make_estimator
from .kernel import kernel_form as packed_form
from .model import Nonlinearities, OutputVector, gain_matrix
from .stepping import (PHI_LIMIT, SUBSTEP_POINTS, IntegralSamples, PolynomialInputs, resolved_output,
                       rk4_linear, substep_points, time_function)

__all__ = ["LTVAdaptiveObserver", "PARTS"]

#: the parameters of paper 001's plant that may be unknown (x(0) always is), in the order of Theta
PARTS = ("k", "b", "m")

#: Gauss-Legendre nodes on [0, 1] of the two-point rule (equal weights 1/2)
GAUSS_NODES = SUBSTEP_POINTS[2:]


class LTVAdaptiveObserver(Block):
    r"""State and parameter observer of paper 001 (filters (2)-(6), regression (7), LS, (10)).

    Parameters
    ----------
    A : callable
        ``A(t) -> (n, n)`` array, the known part of the plant.
    C : array_like, shape (n,), or callable
        Output vector, ``y = C^T x``, or ``C(t) -> (n,)`` array (the paper's ``C(t)``).
    L : callable
        ``L(t) -> (n,)`` array making ``A0(t) = A(t) - L(t) C^T(t)`` uniformly stable
        (Assumptions 3-4; a marginally stable ``A0`` such as the example's ``[[0, 1], [-9, 0]]``
        is accepted).
    f : callable
        ``f(y) -> float``, the known nonlinearity of ``w = m f(y)`` (``f_time``: ``f(t, y)``); or
        returning ``p`` values, the nonlinearities of ``w = sum_i m_i f_i(y, t)``.
    gamma, beta, f0, M : float
        Estimator gains: adaptation gain (``alpha`` in the paper's example), forgetting
        factor, ``F(0) = I / f0``, bound on ``F``.
    x_hat0, k_hat0, b_hat0, m_hat0 : array_like, optional
        Initial estimates (zeros by default), vectors of ``n`` (``m_hat0``: ``n x p``);
        ``Theta_hat(0) = [-x_hat0; k_hat0; b_hat0; m_hat0 columns]`` and ``x_hat(0) = x_hat0``.
    max_substep : float
        Longest RK4 sub-step inside a communication step, s.
    max_dy : float
        Largest change of ``y`` over one sub-step (units of ``y``).
    input_degree : int
        Degree of the polynomials through the last communication points that ``y`` and ``u``
        follow inside a step when the master interpolates
        (:class:`~observers.ltv.stepping.PolynomialInputs`; 2: parabolas).
    substep_budget : int
        Most RK4 sub-steps one communication step may take (a longer step is refused).
    f_correction : bool
        Resolve inside a step the fast part of ``y`` that ``m f(y)`` drives, with the estimate
        ``C^T m_hat`` (:func:`~observers.ltv.stepping.resolved_output`): the polynomial then
        interpolates ``y - C^T m_hat int f(y)``.  For outputs that ``f(y)`` makes oscillate
        faster than the samples (paper case: 1e-3 s steps instead of 1e-4 s); False: the
        polynomial through the samples of ``y``.  One nonlinearity of ``y`` and a constant ``C`` only.
    converged_tolerance : float
        ``converged`` is 1 once the guaranteed bound on ``|Theta_hat - Theta|_2`` is at most this.
    theta_bound : float
        A-priori bound on every entry of ``Theta = [-x(0); k; b; m]``: ``|Theta_i| <= theta_bound``.
    regression_error_bound : float
        A-priori bound on the error of regression (7), ``|z - Psi Theta|`` (noise, model error);
        0: the regression is exact.
    unknowns : sequence of str
        Which of ``k``, ``b``, ``m`` are unknown (``x(0)`` always is); default all three.  The
        others are known: give their values as ``k``, ``b``, ``m``.  Their filters move to the
        left side of (7), ``z = y - C^T (xi + sum_known W_j v_j)``, and ``Theta`` holds only
        ``[-x(0); unknowns]`` (no dummy unknowns).
    k, b, m : array_like, optional
        Values of the known parameters (exactly those not in ``unknowns``): vectors of ``n``, ``m``
        an ``n x p`` matrix (a vector when ``p = 1``).
    estimator : str
        ``"least-squares"`` (the paper's: ``gamma``, ``beta``, ``f0``, ``M``), ``"drem"`` (DREM on a
        Kreisselmeier extension of rate ``extension_rate``, gain ``gamma``) or ``"gradient"`` (gain
        ``gamma``); :mod:`observers.ltv.estimators`.
    extension_rate : float
        ``a`` of DREM's extension ``Phi_e' = -a Phi_e + Psi^T Psi`` (1/s; ``drem`` only).
    delta_floor : float
        DREM's normalised gain ``gamma / (delta_floor^2 + Delta^2)`` (``drem`` only; default
        :data:`~observers.ltv.estimators.DELTA_FLOOR`; 0: the raw gain ``gamma``).
    f_time : bool
        ``f`` depends on the time too, ``w = m f(y, t)``: it is called ``f(t, y)`` (no ``f_correction``).

    Notes
    -----
    Ports: inputs ``u``, ``y`` (scalars); outputs ``x_hat`` (n), ``theta_hat`` (``[-x(0); unknowns]``),
    the parts ``k_hat``, ``b_hat``, ``m_hat`` (n p: ``[m_1; ...; m_p]``), ``x0_hat``, and
    (least squares only) ``F_max``, the largest eigenvalue of the gain ``F`` (bounded by ``M``; watch it
    under noise); then the diagnostics contract (docs/estimation.md, "Diagnostics"): ``excitation``
    and ``converged`` (1 once the estimator's guaranteed error bound is at most ``converged_tolerance``,
    else 0), per estimator in :mod:`observers.ltv.estimators`.
    """

    not_state = ("A", "L", "f", "C", "n", "p", "nonlinearities", "_offsets", "max_substep", "max_dy", "substep_budget", "_forcing", "f_correction",
                 "converged_tolerance", "regression_error_bound", "initial_error", "unknowns", "_columns",
                 "_known_columns", "_known", "least_squares", "f_time")
    state_optional = {"_memo_key": None, "_memo": None}

    def __init__(self, A, C, L, f, gamma=1000.0, beta=1.0, f0=0.1, M=1e12, x_hat0=None, k_hat0=None,
                 b_hat0=None, m_hat0=None, max_substep=1e-3, max_dy=0.2, input_degree=2,
                 substep_budget=DEFAULT_SUBSTEP_BUDGET, f_correction=False, converged_tolerance=1e-3,
                 theta_bound=100.0, regression_error_bound=0.0, unknowns=PARTS, k=None, b=None, m=None,
                 estimator="least-squares", extension_rate=1.0, f_time=False, delta_floor=DELTA_FLOOR):
        self.C = OutputVector(C)
        n = self.n = self.C.n
        self.A = time_function("A", A, (n, n))
        self.L = time_function("L", L, (n,))
        self.f_time = bool(f_time)
        self.nonlinearities = Nonlinearities(f, self.f_time)
        self.f = f
        p = self.p = self.nonlinearities.count
        require_assumptions(self.A, self.L, self.C.at)
        # Theta = [theta; k; b; m_1; ...; m_p]: where each part starts, and its size
        self._offsets = {"theta": (0, n), "k": (n, n), "b": (2 * n, n), "m": (3 * n, n * p)}
        self.max_substep = require_positive("max_substep", max_substep)
        self.max_dy = require_positive("max_dy", max_dy)
        self.substep_budget = require_budget(substep_budget)
        self.unknowns, known = _split_unknowns(unknowns, {"k": k, "b": b, "m": m}, n, p)
        starts = {"k": k_hat0, "b": b_hat0, "m": m_hat0}
        for name in known:
            if starts[name] is not None:
                raise ParameterError(f"{name}_hat0: {name} is known (not in unknowns); it has no estimate")
        initial = [-(np.zeros(n) if x_hat0 is None else as_vector("x_hat0", x_hat0, n))] \
            + [np.zeros(self._offsets[name][1]) if starts[name] is None else _part("m_hat0" if name == "m" else
               f"{name}_hat0", starts[name], n, p) for name in self.unknowns]
        theta0 = np.concatenate(initial)
        self._columns = None if len(self.unknowns) == len(PARTS) else self._part_columns(("theta",) + self.unknowns)
        self._known_columns = self._part_columns(tuple(known))
        self._known = np.concatenate([known[name] for name in known]) if known else np.zeros(0)
        self.converged_tolerance = require_positive("converged_tolerance", converged_tolerance)
        self.regression_error_bound = require_positive("regression_error_bound", regression_error_bound, allow_zero=True)
        self.estimator = make_estimator(estimator, theta0, gamma, beta, f0, M, extension_rate,
                                        self.regression_error_bound, delta_floor)
        self.least_squares = estimator == ESTIMATORS[0]
        # |Theta_hat(0) - Theta|_2 <= | |Theta_hat(0)| + theta_bound |_2
        self.initial_error = float(np.linalg.norm(np.abs(theta0) + require_positive("theta_bound", theta_bound)))
        # S = [xi, W] = [xi, -Phi, eta, zeta, rho_1, ..., rho_p], n x (1 + (3 + p) n)
        self.S = np.zeros((n, 1 + (3 + p) * n))
        self.S[:, 1:1 + n] = -np.eye(n)
        rows = np.arange(n)
        forcing = np.zeros((2 + p, n, self.S.shape[1]))  # where y, u and f_i(y) enter G (identity blocks)
        for k in range(2 + p):
            forcing[k, rows, 1 + (k + 1) * n + rows] = 1.0
        self._forcing = forcing.reshape(2 + p, -1)
        self.inputs = PolynomialInputs(input_degree)
        self.f_correction = bool(f_correction)
        if self.f_correction and (self.f_time or p > 1 or self.C.varies):
            raise ParameterError("f_correction: resolves the fast part of y that m f(y) drives for one f of y only "
                                 "and a constant C; this plant has " + ("f depending on t" if self.f_time else
                                 f"{p} nonlinearities" if p > 1 else "C(t)") + " (give f_correction = 0)")
        self.integral = IntegralSamples(self.inputs.degree)   # int f(y) at the last samples (f_correction)
        self._memo_key, self._memo = None, None
        self.input_sizes = {"u": 1, "y": 1}
        self.output_sizes = {"x_hat": n, "theta_hat": theta0.size, "k_hat": n, "b_hat": n, "m_hat": n * p, "x0_hat": n,
                             **({"F_max": 1} if self.least_squares else {}), "excitation": 1, "converged": 1}

    # ------------------------------------------------------------------ equations
    def _part_columns(self, names) -> np.ndarray:
        """The entries of ``Theta`` that hold the parts ``names`` (in that order)."""
        ranges = [np.arange(first, first + size) for first, size in map(self._offsets.__getitem__, names)]
        return np.concatenate(ranges) if ranges else np.zeros(0, dtype=np.intp)

    def _evaluate(self, t: float, y: float, u: float):
        """``(A0(t), G(t))`` of the filters ``S' = A0 S + G``: (2)-(6) with inputs ``y``, ``u``."""
        L = np.asarray(self.L(t), dtype=float)
        A0 = np.asarray(self.A(t), dtype=float) - np.outer(L, self.C.at(t))
        # eta' = A0 eta + I y, zeta' = A0 zeta + I u, rho_i' = A0 rho_i + I f_i(y, t), (-Phi)' = A0 (-Phi)
        G = (np.array((y, u, *self.nonlinearities.values(t, y))) @ self._forcing).reshape(self.S.shape)
        G[:, 0] = L * y                      # xi' = A0 xi + L y
        return A0, G

    def regression(self, S: np.ndarray, y: float, t: float = 0.0) -> tuple[float, np.ndarray]:
        """Regression (7): ``z = y - C^T(t) xi`` and ``Psi = C^T(t) W``."""
        C = self.C.at(t)
        return y - C @ S[:, 0], C @ S[:, 1:]

    def full_theta(self) -> np.ndarray:
        """``[-x0_hat; k; b; m_1; ...; m_p]``: the estimates, and the known values where known."""
        theta = self.estimator.theta_hat
        if self._columns is None:
            return theta
        full = np.zeros((3 + self.p) * self.n)
        full[self._columns] = theta
        full[self._known_columns] = self._known
        return full

    def state_estimate(self) -> np.ndarray:
        """The estimate from (10): ``x_hat = xi + W Theta_hat`` (known parts with their values)."""
        return self.S[:, 0] + self.S[:, 1:] @ self.full_theta()

    # ------------------------------------------------------------------ Block interface
    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        n, estimator = self.n, self.estimator
        theta = self.full_theta().copy()
        converged = estimator.error_bound(self.initial_error, self.regression_error_bound) <= self.converged_tolerance
        found = {"x_hat": self.state_estimate(), "theta_hat": estimator.theta_hat.copy(), "k_hat": theta[n:2 * n],
                 "b_hat": theta[2 * n:3 * n], "m_hat": theta[3 * n:], "x0_hat": -theta[:n]}
        if self.least_squares:
            found["F_max"] = np.array([estimator.F_max])
        return {**found, "excitation": np.array([estimator.excitation]), "converged": np.array([float(converged)])}

    def advance(self, t: float, h: float, inputs: Mapping[str, Segment]) -> None:
        polynomials, history = self.inputs.step(t, h, inputs)
        y, u = polynomials["y"], polynomials["u"]
        count = substep_count(h, self.max_substep, y.max_rate(), self.max_dy, self.substep_budget)
        dt = h / count
        y_inside, integral = self._output_inside(t, h, count, y, history)
        start = self._memo if self._continues(t, y.start, u.start) else self._evaluate(t, y.start, u.start)
        S, at_nodes = self.S, []
        for i, (y_middle, y_end, *_) in enumerate(y_inside):
            middle = self._evaluate(t + (i + 0.5) * dt, y_middle, u.at((i + 0.5) * dt))
            end = self._evaluate(t + (i + 1) * dt, y_end, u.at((i + 1) * dt))
            S, inside = rk4_linear(S, dt, start, middle, end, SUBSTEP_POINTS[2:])
            at_nodes += inside
            start = end
        finite_signal("filters (2)-(6)", S)
        phi = np.abs(S[:, 1:1 + self.n]).max()
        if phi > PHI_LIMIT:
            raise ParameterError(f"L: the filter transition matrix Phi reached {phi:.3g} at t = {t + h:g}: "
                                 f"A0(t) = A(t) - L(t) C^T is not uniformly stable")
        # regression (7) at the Gauss nodes of every sub-step, all at once: z = y - C^T xi, Psi = C^T W
        CS = self._output_rows(t, dt, count, np.array(at_nodes))
        y_nodes = np.array([value for points in y_inside for value in points[2:]])
        weights = _quadrature_weights(count, h, self.estimator.forgetting)
        estimator = copy.copy(self.estimator)          # committed only if the whole step succeeds
        z, Psi = y_nodes - CS[:, 0], CS[:, 1:]
        if self._columns is not None:                    # known parts of (10) to the left side of (7)
            z, Psi = z - Psi[:, self._known_columns] @ self._known, Psi[:, self._columns]
        estimator.update(weights * z, weights[:, None] * Psi, h)
        self.S, self.estimator, self.integral = S, estimator, integral
        self._memo_key, self._memo = (t + h, y.at(h), u.at(h)), end
        self.inputs = history

    def kernel_form(self):
        """The packed form of the compiled step kernel (:mod:`observers.ltv.kernel`), or None: Python steps."""
        return packed_form(self)

    def _output_inside(self, t: float, h: float, count: int, y, history):
        """``y`` at :data:`SUBSTEP_POINTS` of every sub-step, and the samples of ``int f(y)`` after the step.

        Without ``f_correction``: the polynomial through the samples.  With it, the fast part that
        ``m f(y)`` drives is resolved (:func:`~observers.ltv.stepping.resolved_output`) with the
        estimate ``mu = C^T m_hat``, unless ``|mu| h > 0.5`` (a wild estimate early on: the
        polynomial alone then), which also keeps the RK4 of ``int f(y)`` stable.
        """
        if not self.f_correction:
            return substep_points(y, count), self.integral
        times, _ = history.history("y")                # the polynomial's nodes, ending at t + h
        mu = float(self.C.constant @ self.full_theta()[3 * self.n:])
        past = self.integral.at(times[:-1]) if abs(mu) * h <= 0.5 else None
        y_inside, change = resolved_output(self.f, y, times, past, mu, count)
        return y_inside, self.integral.after(t, h, change)

    def _output_rows(self, t: float, dt: float, count: int, S_nodes: np.ndarray) -> np.ndarray:
        """``C^T(s) S(s)`` at the Gauss nodes ``s`` of the ``count`` sub-steps of length ``dt`` after ``t``."""
        if not self.C.varies:
            return self.C.constant @ S_nodes
        times = t + (np.arange(count)[:, None] + np.array(GAUSS_NODES)[None, :]).ravel() * dt
        return np.einsum("ki,kij->kj", np.array([self.C.at(s) for s in times]), S_nodes)

    def _continues(self, t: float, y: float, u: float) -> bool:
        """The step starts where the previous one ended (to round-off): its end coefficients apply."""
        key = self._memo_key
        return key is not None and all(abs(a - b) <= 1e-12 * max(1.0, abs(a)) for a, b in zip(key, (t, y, u)))


def _part(name: str, value, n: int, p: int) -> np.ndarray:
    """A part of ``Theta`` from its value: a vector of ``n``, or (``m``) the columns of the ``n x p`` gains."""
    if name.startswith("m"):
        return gain_matrix(name, value, n, p).T.ravel()
    return as_vector(name, value, n)


def _split_unknowns(unknowns, values: dict, n: int, p: int) -> tuple[tuple[str, ...], dict[str, np.ndarray]]:
    """``(unknowns in the order k, b, m, {known name: value})``; every mistake names the field."""
    names = [unknowns] if isinstance(unknowns, str) else list(unknowns)
    wrong = [name for name in names if name not in PARTS]
    if wrong or len(set(names)) != len(names):
        raise ParameterError(f"unknowns: expected distinct names among {list(PARTS)}, got {names}")
    known = {}
    for name in PARTS:
        if name in names and values[name] is not None:
            raise ParameterError(f"{name}: {name} is unknown (in unknowns); give no value, or remove it from unknowns")
        if name not in names:
            if values[name] is None:
                raise ParameterError(f"{name}: {name} is known (not in unknowns); its value is required")
            known[name] = _part(name, values[name], n, p)
    return tuple(name for name in PARTS if name in names), known


@lru_cache(maxsize=64)
def _quadrature_weights(count: int, h: float, beta: float) -> np.ndarray:
    r"""Scales of the ``2 count`` Gauss rows of a step so that one held-regression update is the
    exact information-form step.

    Over a step the law adds ``gamma int_0^h exp(-beta (h - s)) Psi^T Psi(s) ds`` to ``P``; the
    estimator adds ``gamma h phi1(beta h) Phi^T Phi`` for a held ``Phi``.  Row ``i`` at
    ``s_i`` (Gauss node of sub-step ``j``, weight ``dt/2``) is scaled by
    ``sqrt(dt/2 exp(-beta (h - s_i)) / (h phi1(beta h)))``: Gauss quadrature of the weighted
    integral (the unweighted step average was off by ``O(beta h)`` in the transient).
    """
    dt = h / count
    nodes = (np.arange(count)[:, None] + np.array(GAUSS_NODES)[None, :]).ravel() * dt
    weights = np.sqrt(0.5 * dt * np.exp(-beta * (h - nodes)) / (h * phi1(beta * h)))
    weights.flags.writeable = False          # cached: shared by every step of this length
    return weights
