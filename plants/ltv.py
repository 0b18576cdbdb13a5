r"""Nonlinear LTV plant of paper 001: ``x' = A(t) x + k C^T x + b u + m f(y)``, ``y = C^T x``.

``A(t)``, ``C`` (or ``C(t)``) and ``f`` are known to the observer; ``k``, ``b``, ``m`` and ``x(0)`` are
the unknowns it estimates.  ``f`` may return ``p`` values, the nonlinearities of
``sum_i m_i f_i(y, t)``, with ``m = [m_1, ..., m_p]`` an ``n x p`` matrix (:mod:`observers.ltv.model`).
The true state ``x`` and the true parameter vector of the
regression (7), ``Theta = [-x(0); k; b; m_1; ...; m_p]``, are outputs so that estimation errors can be
computed.  An optional measurement noise ``v`` (sample-and-hold Gaussian,
:class:`~plants.signals.SampledNoise`) is added to the measured output only:
``y = C^T x + v``; the plant itself evolves with the noise-free ``C^T x``.

A communication step is integrated with RK4 sub-steps, each at most ``max_substep`` long
and short enough for ``C^T x`` to change by at most ``max_dy`` (estimated from ``y'`` at the
step start) -- with ``f = sin`` and ``|y|`` in the thousands, ``f(y)`` oscillates at
hundreds of rad/s and must be resolved.

The example's functions (:func:`A_paper`, :func:`L_paper`, :func:`f_sin`) are referenced from FMU
definitions as ``"plants.ltv:<name>"`` (:mod:`fmus.runtime.callables`); the ``plants`` package is bundled into
every FMU, so they need no ``extra_modules``.  Write your own functions with the same signatures in a
module of yours to observe another plant of the class: ``A(t) -> (n, n)`` and ``L(t) -> (n,)`` arrays,
``f(y) -> float``; ``L(t)`` must make ``A0(t) = A(t) - L(t) C^T`` uniformly stable (Assumptions 3-4;
here ``A0 = [[0, 1], [-9, 0]]`` for ``C = [1; 0]``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Mapping

import numpy as np

from obsfmu.observers.block import Block, Segment
from obsfmu.observers.checks import SignalError, as_vector, require_positive
from obsfmu.observers.integrators import DEFAULT_SUBSTEP_BUDGET, require_budget, rk4_step, substep_count
from obsfmu.observers.ltv.kernel import plant_kernel_form
from obsfmu.observers.ltv.model import Nonlinearities, OutputVector, gain_matrix
from obsfmu.observers.ltv.stepping import PolynomialInputs, time_function

from .signals import SampledNoise

__all__ = ["OutputNonlinearLTVPlant", "A_paper", "L_paper", "f_sin", "C_PAPER"]

# -- the functions of the paper's example (Kozachek, Bobtsov, Nikolaev 2023) ----------------------
#: output vector of the example, ``y = C^T x = x1``
C_PAPER = (1.0, 0.0)


def A_paper(t: float) -> np.ndarray:
    """``A(t) = [[2 - sin t, 1], [-8 + cos t, 0]]``."""
    return np.array([[2.0 - math.sin(t), 1.0], [-8.0 + math.cos(t), 0.0]])


def L_paper(t: float) -> np.ndarray:
    """``L(t) = [2 - sin t; 1 + cos t]``, so that ``A(t) - L(t) C^T = [[0, 1], [-9, 0]]``."""
    return np.array([2.0 - math.sin(t), 1.0 + math.cos(t)])


def f_sin(y: float) -> float:
    """``f(y) = sin y`` (the example's ``w = m sin y``)."""
    return math.sin(y)


class OutputNonlinearLTVPlant(Block):
    """Plant (1) of paper 001 with known ``A(t)``, ``C``, ``f`` and unknown ``k``, ``b``, ``m``, ``x0``.

    Parameters
    ----------
    A : callable
        ``A(t) -> (n, n)`` array.
    C : array_like, shape (n,), or callable
        Output vector, or ``C(t) -> (n,)`` array.
    f : callable
        ``f(y) -> float`` (``f_time``: ``f(t, y) -> float``), or returning ``p`` values.
    k, b, x0 : array_like, shape (n,)
        Output injection ``k C^T x``, input vector, initial state.
    m : array_like, shape (n,) or (n, p)
        The nonlinearities' gains ``[m_1, ..., m_p]``.
    noise : SampledNoise, optional
        Measurement noise added to the output ``y``.
    max_substep : float
        Longest RK4 sub-step, s.
    max_dy : float
        Largest change of ``C^T x`` over one sub-step.
    input_degree : int
        Degree of the polynomial ``u`` follows inside a step when the master interpolates.
    substep_budget : int
        Most sub-steps one communication step may take (a longer step is refused).
    f_time : bool
        ``f`` depends on the time too: it is called ``f(t, y)``.

    Notes
    -----
    Ports: input ``u`` (scalar); outputs ``y`` (measured, scalar), ``x`` (n) and ``theta``
    (``(3 + p) n``, the true ``Theta = [-x(0); k; b; m_1; ...; m_p]``).
    """

    not_state = ("A", "f", "f_time", "nonlinearities", "C", "k", "b", "m", "theta", "_kbm", "noise", "max_substep", "max_dy",
                 "substep_budget")

    def __init__(self, A: Callable, C, f: Callable, k, b, m, x0, noise: SampledNoise | None = None,
                 max_substep: float = 1e-3, max_dy: float = 0.2, input_degree: int = 2,
                 substep_budget: int = DEFAULT_SUBSTEP_BUDGET, f_time: bool = False):
        self.C = OutputVector(C)
        n = self.C.n
        self.A = time_function("A", A, (n, n))
        self.f_time = bool(f_time)
        self.f = f
        self.nonlinearities = Nonlinearities(f, self.f_time)
        self.k, self.b, x0 = (as_vector(name, value, n) for name, value in (("k", k), ("b", b), ("x0", x0)))
        self.m = gain_matrix("m", m, n, self.nonlinearities.count)
        self.theta = np.concatenate([-x0, self.k, self.b, self.m.T.ravel()])
        self._kbm = np.column_stack([self.k, self.b, self.m])
        self.x = x0.copy()
        self.noise = noise
        self.max_substep = require_positive("max_substep", max_substep)
        self.max_dy = require_positive("max_dy", max_dy)
        self.substep_budget = require_budget(substep_budget)
        self.inputs = PolynomialInputs(input_degree)
        self.input_sizes = {"u": 1}
        self.output_sizes = {"y": 1, "x": n, "theta": self.theta.size}

    def rate(self, t: float, x: np.ndarray, u: float, A: np.ndarray | None = None) -> np.ndarray:
        """Right-hand side of (1): ``A(t) x + k y + b u + sum_i m_i f_i(y, t)``, ``y = C^T(t) x`` (``A``: ``A(t)``
        if known)."""
        y = float(self.C.at(t) @ x)
        A = np.asarray(self.A(t), dtype=float) if A is None else A
        return A @ x + self._kbm @ np.array((y, u, *self.nonlinearities.values(t, y)))

    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        y = np.array([self.C.at(t) @ self.x])
        if self.noise is not None and self.noise.std:
            y = y + self.noise(t)
        return {"y": y, "x": self.x.copy(), "theta": self.theta.copy()}

    def kernel_form(self):
        """The packed form of the compiled step kernel (:func:`observers.ltv.kernel.plant_kernel_form`), or None."""
        return plant_kernel_form(self)

    def advance(self, t: float, h: float, inputs: Mapping[str, Segment]) -> None:
        polynomials, history = self.inputs.step(t, h, inputs)
        u = polynomials["u"]
        matrices = {}                     # A(s) once per distinct time (RK4 asks for each twice)

        def A(s):
            if s not in matrices:
                matrices[s] = np.asarray(self.A(s), dtype=float)
            return matrices[s]

        dy = self.C.at(t) @ self.rate(t, self.x, u.start, A(t))
        count = substep_count(h, self.max_substep, dy, self.max_dy, self.substep_budget)
        x = rk4_step(lambda s, x: self.rate(s, x, u.at(s - t), A(s)), t, self.x, h, count)
        if not np.all(np.isfinite(x)):
            raise SignalError(f"x: the plant state is not finite at t = {t + h:g} (unstable plant?)")
        self.x, self.inputs = x, history
