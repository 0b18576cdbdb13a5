r"""The numerically checkable assumptions of paper 001 on ``A(t)``, ``L(t)``, ``C`` (or ``C(t)``).

* Assumptions 3-4: ``A0(t) = A(t) - L(t) C^T(t)`` uniformly stable.  For a constant ``A0`` (the same
  matrix at every grid point, to round-off) this is decided exactly: every eigenvalue has a negative
  real part, or a zero one and is semisimple (no Jordan block: the paper's example
  ``A0 = [[0, 1], [-9, 0]]`` is marginally, yet uniformly, stable).  For a time-varying ``A0``
  frozen-time eigenvalues in the closed left half-plane on a grid of ``t`` are only *necessary*:
  they catch wrong signs and dimensions, they cannot prove uniform stability of an LTV system (the
  observer also refuses a step after which its transition matrix ``Phi`` has grown beyond
  :data:`~observers.ltv.stepping.PHI_LIMIT`).
* Regression (7) identifies ``x(0)`` only if ``(A0, C^T)`` is observable: checked at every grid point
  (for ``C(t)`` the frozen-time pair ``(A0(t), C^T(t))``: a necessary check, as for ``A0``).
"""

from __future__ import annotations

import numpy as np

from ..checks import ParameterError, unbounded_mode

__all__ = ["require_assumptions", "DEFAULT_TIMES"]

#: the grid the block checks when it is built (the system file checks 200 points of [0, stop_time])
DEFAULT_TIMES = np.linspace(0.0, 10.0, 21)


def _A0(A, L, C: np.ndarray, t: float) -> np.ndarray:
    A0 = np.asarray(A(t), dtype=float) - np.outer(np.asarray(L(t), dtype=float), C)
    if not np.all(np.isfinite(C)):
        raise ParameterError(f"C: C(t) is not finite at t = {t:g}")
    if not np.all(np.isfinite(A0)):
        raise ParameterError(f"L: A0(t) = A(t) - L(t) C^T is not finite at t = {t:g}")
    return A0


def _require_observable(A0: np.ndarray, C: np.ndarray, t: float) -> None:
    observability = np.array([C @ np.linalg.matrix_power(A0, i) for i in range(C.size)])
    rank = np.linalg.matrix_rank(observability)
    if rank < C.size:
        raise ParameterError(f"C: (A0(t), C^T) is not observable at t = {t:g} (the rank of [C^T; C^T A0; ...] is "
                             f"{rank} < n = {C.size}); the regression (7) cannot identify x(0)")


def _unstable(worst: complex, where: str) -> ParameterError:
    return ParameterError(f"L: A0(t) = A(t) - L(t) C^T has the eigenvalue {worst:.6g} {where} (real part > 0); "
                          "choose L(t) so that A0 is uniformly stable (paper 001, Assumptions 3-4)")


def _require_stable_constant(A0: np.ndarray, tolerance: float) -> None:
    """The exact test for a constant ``A0``: Re < 0, or Re = 0 and semisimple."""
    mode = unbounded_mode(A0, tolerance)
    if mode is None:
        return
    if mode.growing:
        raise _unstable(mode.value, "(A0 is constant)")
    raise ParameterError(f"L: A0 = A - L C^T is constant with the eigenvalue {mode.value:.6g} on the imaginary "
                         f"axis {mode.algebraic} times but a Jordan block (solutions grow like t): not uniformly "
                         "stable (paper 001, Assumptions 3-4)")


def require_assumptions(A, L, C, times=DEFAULT_TIMES, tolerance: float = 1e-9) -> str:
    """Refuse ``L`` or ``C`` against the assumptions above on the grid ``times``; say which test applied.

    ``C`` is the output vector, or a function of time returning it (``C(t)``).

    Returns
    -------
    str
        ``"constant"`` (``A0`` is one matrix: the exact test) or ``"frozen-time"`` (the necessary test).

    Raises
    ------
    ParameterError
        Naming ``L`` (an unstable or non-finite ``A0``) or ``C`` (not observable), and the assumption.
    """
    outputs = [np.asarray(C(float(t)) if callable(C) else C, dtype=float) for t in times]
    matrices = [_A0(A, L, C_t, float(t)) for t, C_t in zip(times, outputs)]
    for t, A0, C_t in zip(times, matrices, outputs):
        _require_observable(A0, C_t, float(t))
    first = matrices[0]
    if all(np.abs(A0 - first).max() <= 1e-12 * max(1.0, np.abs(first).max()) for A0 in matrices):
        _require_stable_constant(first, tolerance)
        return "constant"
    for t, A0 in zip(times, matrices):
        eigenvalues = np.linalg.eigvals(A0)
        worst = eigenvalues[np.argmax(eigenvalues.real)]
        if worst.real > tolerance * max(1.0, np.abs(A0).max()):
            raise _unstable(worst, f"at t = {float(t):g}")
    return "frozen-time"
