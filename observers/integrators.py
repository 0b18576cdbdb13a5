"""Integrators that advance continuous dynamics over one communication step.

Inside an FMU the master only sees communication points, so each block must
integrate its own dynamics accurately over a whole step ``h`` (the accuracy
of a co-simulation must not depend on the master taking tiny steps).

* :class:`LinearPropagator` -- exact for LTI dynamics ``x' = A x + B u`` with
  an input that is *linear* over the step, ``u(t0 + s) = u0 + s du``
  (first-order hold; ``du = 0`` is the zero-order hold).  With the augmented
  matrix

      M = [[A, B, 0], [0, 0, I], [0, 0, 0]],   expm(M h) = [[Phi, G0, G1], [0, I, h I], [0, 0, I]]

  the step is ``x(t0 + h) = Phi x + G0 u0 + G1 du`` (Van Loan's method).
* :func:`rk4_step` -- classical Runge-Kutta 4 with equal sub-steps, for
  time-varying or nonlinear dynamics.
* :func:`substep_count` -- how many sub-steps a communication step needs, within the block's
  work budget: every block that sub-steps or iterates calls it *before* doing any work, so
  that no call takes unbounded time (a step of 1e6 s is refused at once, not computed).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from .checks import ParameterError, SignalError

__all__ = ["LinearPropagator", "rk4_step", "expm", "substep_count", "require_budget", "BudgetError",
           "DEFAULT_SUBSTEP_BUDGET"]

#: default of every block's ``substep_budget``: sub-steps one communication step may take
DEFAULT_SUBSTEP_BUDGET = 10_000


class BudgetError(SignalError):
    """A step would need more sub-steps than the block's budget; refused before any work."""


def require_budget(value) -> int:
    """``value`` as a sub-step budget (an integer >= 1); :class:`ParameterError` otherwise."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ParameterError(f"substep_budget: expected an integer >= 1, got {value!r}") from None
    if not (number >= 1 and number == int(number) and number <= 1e12):
        raise ParameterError(f"substep_budget: expected an integer >= 1 (at most 1e12), got {number:g}")
    return int(number)


def substep_count(h: float, max_substep: float = math.inf, rate: float = 0.0, max_change: float = math.inf,
                  budget: int = DEFAULT_SUBSTEP_BUDGET) -> int:
    """Number of equal sub-steps of a step ``h``: each at most ``max_substep`` long, and a signal
    changing at ``rate`` changes by at most ``max_change`` on each.

    Raises :class:`BudgetError` (naming ``substep_budget``) when more than ``budget`` are needed;
    call it before any work so that a refused step costs nothing.
    """
    by_length = h / max_substep
    by_change = abs(rate) * h / max_change if rate else 0.0
    limit = budget * (1.0 + 1e-9)
    if not (by_length <= limit and by_change <= limit):   # also NaN and inf
        needed = by_length if not by_change > by_length else by_change
        why = f"sub-steps of at most max_substep = {max_substep:g}" if by_length >= by_change else \
            f"sub-steps over which the signal (changing at {abs(rate):.3g}/s) moves by at most {max_change:g}"
        raise BudgetError(f"substep_budget: the step h = {h:g} needs {needed:.3g} {why}, more than "
                          f"substep_budget = {budget}; take a shorter step or raise substep_budget")
    return max(1, math.ceil(by_length - 1e-9), math.ceil(by_change - 1e-9))


def expm(M: np.ndarray) -> np.ndarray:
    """``scipy.linalg.expm``, imported on first use: ``scipy.linalg`` costs ~0.15 s CPU to import,
    which every ``obsfmu`` command (and ``obsfmu list``) would otherwise pay."""
    from scipy.linalg import expm as matrix_exponential
    return matrix_exponential(M)


class LinearPropagator:
    """Exact propagation of ``x' = A x + B u`` for inputs linear over the step.

    The matrices for a step length are computed once and cached (a
    co-simulation uses one step length, an adaptive master a few powers of
    two of it).  The cache is a pure function of ``(A, B, h)``, so copies of a
    block share their propagator (``copy.deepcopy`` returns it unchanged).
    """

    CACHE_SIZE = 64

    def __deepcopy__(self, memo):
        return self

    def __init__(self, A: np.ndarray, B: np.ndarray):
        self.A = np.asarray(A, dtype=float)
        self.B = np.asarray(B, dtype=float).reshape(self.A.shape[0], -1)
        self._cache: dict[float, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def matrices(self, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(Phi, G0, G1)`` for step ``h``."""
        cached = self._cache.get(h)
        if cached is None:
            n, m = self.B.shape
            M = np.zeros((n + 2 * m, n + 2 * m))
            M[:n, :n] = self.A
            M[:n, n:n + m] = self.B
            M[n:n + m, n + m:] = np.eye(m)
            E = expm(M * h)
            cached = (E[:n, :n], E[:n, n:n + m], E[:n, n + m:])
            if len(self._cache) >= self.CACHE_SIZE:
                self._cache.clear()
            self._cache[h] = cached
        return cached

    def step(self, x: np.ndarray, h: float, u0: np.ndarray, du: np.ndarray | None = None) -> np.ndarray:
        """State at ``t0 + h`` from ``x(t0)`` and the input ``u0 + s du``."""
        Phi, G0, G1 = self.matrices(h)
        x_next = Phi @ x + G0 @ u0
        if du is not None:
            x_next = x_next + G1 @ du
        return x_next


def rk4_step(f: Callable[[float, np.ndarray], np.ndarray], t: float, x: np.ndarray,
             h: float, substeps: int = 1) -> np.ndarray:
    """Advance ``x' = f(t, x)`` from ``t`` to ``t + h`` with ``substeps`` RK4 steps."""
    dt = h / substeps
    for i in range(substeps):
        s = t + i * dt
        k1 = f(s, x)
        k2 = f(s + dt / 2, x + dt / 2 * k1)
        k3 = f(s + dt / 2, x + dt / 2 * k2)
        k4 = f(s + dt, x + dt * k3)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x
