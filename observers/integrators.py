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
* :func:`rk4_controlled` -- the same RK4 sub-steps under local error control (the embedded
  third-order solution of the same stages): a sub-step whose error estimate exceeds
  ``atol + rtol |x|`` is taken again shorter, so a stiff or fast plant is integrated right or
  refused by its sub-step budget, never silently wrong.
* :func:`substep_count` -- how many sub-steps a communication step needs, within the block's
  work budget: every block that sub-steps or iterates calls it *before* doing any work, so
  that no call takes unbounded time (a step of 1e6 s is refused at once, not computed).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from .checks import ParameterError, SignalError

__all__ = ["LinearPropagator", "rk4_step", "rk4_controlled", "expm", "substep_count", "sample_count", "require_budget", "BudgetError",
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


def sample_count(h: float, sample_time: float, budget: int = DEFAULT_SUBSTEP_BUDGET) -> int:
    """Number of samples of a discrete block (sample time ``T``) in a communication step ``h``.

    A step must cover whole samples (to a relative 1e-9): else :class:`SignalError` naming
    ``sample_time``; more than ``budget`` samples: :class:`BudgetError`.  Call it before any work.
    """
    count = round(h / sample_time) if math.isfinite(h) else 0
    if count < 1 or not math.isclose(count * sample_time, h, rel_tol=1e-9):
        raise SignalError(f"sample_time: a step of a discrete block covers whole samples of T = {sample_time:g}; "
                          f"h = {h:g} is {h / sample_time:.6g} samples")
    if count > budget:
        raise BudgetError(f"substep_budget: the step h = {h:g} is {count} samples of T = {sample_time:g}, more "
                          f"than substep_budget = {budget}")
    return count


#: Pade degree m -> (largest scaled size for which the [m/m] Pade approximant of expm is accurate to
#: double precision, its coefficients b_j, 1 / |c_(2m+1)| of its backward-error series) -- Al-Mohy and
#: Higham (2009), "A new scaling and squaring algorithm for the matrix exponential", SIAM J. Matrix
#: Anal. Appl. 31(3), Algorithm 5.1 and Table 3.1 (the algorithm of scipy.linalg.expm).
_PADE = {
    3: (1.495585217958292e-2, (120.0, 60.0, 12.0, 1.0), 100800.0),
    5: (2.539398330063230e-1, (30240.0, 15120.0, 3360.0, 420.0, 30.0, 1.0), 10059033600.0),
    7: (9.504178996162932e-1, (17297280.0, 8648640.0, 1995840.0, 277200.0, 25200.0, 1512.0, 56.0, 1.0),
        4487938430976000.0),
    9: (2.097847961257068e0, (17643225600.0, 8821612800.0, 2075673600.0, 302702400.0, 30270240.0, 2162160.0,
                              110880.0, 3960.0, 90.0, 1.0), 5914384781877411840000.0),
    13: (4.25, (64764752532480000.0, 32382376266240000.0, 7771770303897600.0, 1187353796428800.0,
                129060195264000.0, 10559470521600.0, 670442572800.0, 33522128640.0, 1323241920.0, 40840800.0,
                960960.0, 16380.0, 182.0, 1.0), 113250775606021113483283660800000000.0),
}


def _norm1(A: np.ndarray) -> float:
    return float(np.abs(A).sum(axis=0).max()) if A.size else 0.0


def _extra_squarings(A: np.ndarray, m: int) -> int:
    """``ell(A, m)`` of Al-Mohy and Higham (2009), eq. (5.1): extra scaling a non-normal ``A`` needs
    for the degree-``m`` approximant (0 for most matrices)."""
    norm = _norm1(A)
    if norm == 0.0:
        return 0
    column_sums = np.ones(A.shape[0])
    absolute = np.abs(A)
    for _ in range(2 * m + 1):                    # || |A|^(2m+1) ||_1, exactly (a non-negative matrix)
        column_sums = column_sums @ absolute
    alpha = float(column_sums.max()) / (norm * _PADE[m][2])
    if alpha == 0.0:
        return 0
    return max(0, math.ceil(math.log2(alpha / 2.0 ** -53) / (2 * m)))


def expm(M: np.ndarray) -> np.ndarray:
    """Matrix exponential by scaling and squaring with Pade approximants (Al-Mohy and Higham 2009,
    Algorithm 5.1, with exact norms of the matrix powers).

    numpy only: ``scipy.linalg`` costs ~0.15-0.5 s CPU to import (scipy >= 1.15 also imports
    ``numpy.testing`` and ``numpy.f2py`` through its array-API layer), which every LTI FMU, the
    config checks and ``obsfmu run ship`` would otherwise pay.  Agrees with ``scipy.linalg.expm``
    (the same algorithm) to ~1e-13 relative, also on the highly non-normal closed loops of
    high-order designs (``tests/observers/test_integrators_expm.py``).
    """
    A = np.asarray(M, dtype=float)
    if A.ndim != 2 or A.shape[0] != A.shape[1]:
        raise ValueError(f"expm: expected a square matrix, got shape {A.shape}")
    if not np.all(np.isfinite(A)):
        return np.full_like(A, np.nan)
    identity = np.eye(A.shape[0])
    A2 = A @ A
    A4 = A2 @ A2
    A6 = A4 @ A2
    d4, d6 = _norm1(A4) ** 0.25, _norm1(A6) ** (1 / 6)
    eta = max(d4, d6)
    for m in (3, 5):
        if eta <= _PADE[m][0] and _extra_squarings(A, m) == 0:
            return _pade(A, m, identity, [identity, A2, A4, A6])
    A8 = A4 @ A4
    d8 = _norm1(A8) ** 0.125
    eta = max(d6, d8)
    for m in (7, 9):
        if eta <= _PADE[m][0] and _extra_squarings(A, m) == 0:
            return _pade(A, m, identity, [identity, A2, A4, A6, A8])
    eta = min(eta, max(d8, _norm1(A4 @ A6) ** 0.1))
    squarings = max(0, math.ceil(math.log2(eta / _PADE[13][0]))) if eta > 0.0 else 0
    squarings += _extra_squarings(A / 2.0 ** squarings, 13)
    scale = 2.0 ** -squarings
    R = _pade(A * scale, 13, identity, [identity, A2 * scale ** 2, A4 * scale ** 4, A6 * scale ** 6])
    for _ in range(squarings):
        R = R @ R
    return R


def _pade(A: np.ndarray, m: int, identity: np.ndarray, even: list[np.ndarray]) -> np.ndarray:
    """The [m/m] Pade approximant ``(V - U)^-1 (V + U)`` of ``expm(A)`` (U odd, V even powers of A;
    ``even`` = I, A^2, A^4, ...)."""
    b = _PADE[m][1]
    if m < 13:
        U = A @ sum(b[2 * k + 1] * P for k, P in enumerate(even[:m // 2 + 1]))
        V = sum(b[2 * k] * P for k, P in enumerate(even[:m // 2 + 1]))
    else:
        _, A2, A4, A6 = even
        U = A @ (A6 @ (b[13] * A6 + b[11] * A4 + b[9] * A2) + b[7] * A6 + b[5] * A4 + b[3] * A2 + b[1] * identity)
        V = A6 @ (b[12] * A6 + b[10] * A4 + b[8] * A2) + b[6] * A6 + b[4] * A4 + b[2] * A2 + b[0] * identity
    return np.linalg.solve(V - U, V + U)


#: the largest ||M h|| the exact discretisation takes (its matrix powers overflow near 1e154)
_LONGEST = 1e100


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
            size = _norm1(M) * h
            if not size <= _LONGEST:               # also NaN and inf: expm's squarings would overflow
                raise SignalError(f"the step h = {h:g} is too long for the exact discretisation: ||[A, B] h|| = "
                                  f"{size:.3g}, more than {_LONGEST:.0e}; take a shorter step")
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
        s, end = t + i * dt, t + (i + 1) * dt   # end: the next sub-step's s, the same float (caches of f(t) hit)
        k1 = f(s, x)
        k2 = f(s + dt / 2, x + dt / 2 * k1)
        k3 = f(s + dt / 2, x + dt / 2 * k2)
        k4 = f(end, x + dt * k3)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


def rk4_controlled(f: Callable[[float, np.ndarray], np.ndarray], t: float, x: np.ndarray, h: float,
                   substeps: int, rtol: float, atol: float, budget: int = DEFAULT_SUBSTEP_BUDGET) -> np.ndarray:
    """Advance ``x' = f(t, x)`` from ``t`` to ``t + h`` by RK4 sub-steps of at most ``h / substeps``, each
    accepted only if its local error estimate is within ``atol + rtol max(|x|, |x_next|)`` (every component).

    The estimate is the difference to the embedded third-order solution of the same stages and
    ``k5 = f(t + dt, x_next)`` (which is the next sub-step's ``k1``: one evaluation more per call)::

        x_next = x + dt (k1 + 2 k2 + 2 k3 + k4) / 6,   x3 = x + dt (k1 + 2 k2 + 2 k3 + k5) / 6,
        error ~ x_next - x3 = dt (k4 - k5) / 6

    (``b3 = [1/6, 1/3, 1/3, 0, 1/6]`` meets the four third-order conditions on RK4's nodes and matrix).
    A rejected sub-step is retried at ``dt (0.9 / ratio)^(1/4)`` (at least ``dt / 10``); accepted ones grow
    back to ``h / substeps`` at most.  While nothing is rejected the sub-steps and the result are those of
    :func:`rk4_step`.  More than ``budget`` attempts: :class:`BudgetError` naming ``substep_budget``,
    ``rtol`` and ``atol`` (a stiff plant needs sub-steps of about ``2.8 / |lambda|``).  A non-finite
    state is returned as it is (the caller refuses it).
    """
    nominal = h / substeps
    dt, s, stop, attempts, rejected = nominal, t, t + h, 0, False
    k1 = f(t, x)
    i = 0
    while True:
        if not rejected:                                   # rk4_step's grid, to the last bit
            s, end, dt = t + i * nominal, t + (i + 1) * nominal, nominal
        else:
            end = s + dt if s + dt < stop - 1e-12 * abs(h) else stop
            dt = end - s
        attempts += 1
        if attempts > budget:
            raise BudgetError(f"substep_budget: the step h = {h:g} needs more than substep_budget = {budget} "
                              f"sub-steps to keep the local error within rtol = {rtol:g}, atol = {atol:g} (the last "
                              f"ones {dt:.3g} long): the plant is stiff or very fast here; raise rtol/atol or "
                              f"substep_budget, or take a shorter step")
        k2 = f(s + dt / 2, x + dt / 2 * k1)
        k3 = f(s + dt / 2, x + dt / 2 * k2)
        k4 = f(end, x + dt * k3)
        x_next = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        if not np.all(np.isfinite(x_next)):
            return x_next
        k5 = f(end, x_next)
        scale = atol + rtol * np.maximum(np.abs(x), np.abs(x_next))
        ratio = float(np.max(np.abs(dt / 6 * (k4 - k5)) / scale)) if x.size else 0.0
        if not ratio <= 1.0:                               # NaN too: shorter
            rejected = True
            dt *= max(0.1, 0.9 * ratio ** -0.25) if np.isfinite(ratio) else 0.1
            continue
        x, k1, s = x_next, k5, end
        i += 1
        if s >= stop or (not rejected and i == substeps):
            return x
        if rejected:
            dt = min(nominal, dt * min(5.0, 0.9 * ratio ** -0.25 if ratio > 0 else 5.0))
