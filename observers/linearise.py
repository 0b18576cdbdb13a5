r"""The linearisation of ``x' = f(t, x, u, p)``, ``y = h(t, x, u, p)`` at an operating point, checked.

.. math:: A = \partial f / \partial x,\ B = \partial f / \partial u,\ C = \partial h / \partial x,\
          D = \partial h / \partial u \quad \text{at } (t_0, x_0, u_0),

so that near the point ``x' ~ f_0 + A (x - x_0) + B (u - u_0)``, ``y ~ y_0 + C (x - x_0) + D (u - u_0)``.
Each column is a central difference of step ``d = 1e-5 max(1, |z_j|)``; the same with ``d / 4`` must agree
with it (their difference estimates the truncation error, ``O(d^2)``) to ``1e-6`` of the column's size, and the
one-sided differences forward and backward must agree to ``1e-3`` of it (a kink such as ``abs(x)`` at 0 is
invisible to central differences, not to these): else the entry is refused by name.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .checks import ParameterError

__all__ = ["Linearisation", "linearise"]

#: relative step of the central differences, and the agreement asked of the d and d / 4 estimates
_STEP, _AGREEMENT, _KINK = 1e-5, 1e-6, 1e-3


@dataclass(frozen=True)
class Linearisation:
    """``A, B, C, D`` at the operating point and the values ``f_0 = f(x_0, u_0)``, ``y_0 = h(x_0, u_0)`` there."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    f0: np.ndarray
    y0: np.ndarray


def _jacobian(function, z0: np.ndarray, where: str, variable: str) -> np.ndarray:
    """Central differences of ``function(z)`` at ``z0``, column by column, checked against a step four times
    smaller."""
    columns = []
    for j in range(z0.size):
        step = _STEP * max(1.0, abs(z0[j]))

        def difference(d: float) -> np.ndarray:
            e = np.zeros(z0.size)
            e[j] = d
            return (np.asarray(function(z0 + e), dtype=float) - np.asarray(function(z0 - e), dtype=float)) / (2 * d)
        coarse, fine = difference(step), difference(step / 4)
        e = np.zeros(z0.size)
        e[j] = step
        at = np.asarray(function(z0), dtype=float)
        forward = (np.asarray(function(z0 + e), dtype=float) - at) / step
        backward = (at - np.asarray(function(z0 - e), dtype=float)) / step
        if not (np.all(np.isfinite(coarse)) and np.all(np.isfinite(fine))):
            raise ParameterError(f"{where}: the derivative with respect to {variable}[{j + 1}] is not finite at the "
                                 "operating point")
        scale = max(1.0, float(np.max(np.abs(fine))))
        if np.max(np.abs(coarse - fine)) > _AGREEMENT * scale or np.max(np.abs(forward - backward)) > _KINK * scale:
            raise ParameterError(f"{where}: the derivative with respect to {variable}[{j + 1}] changes with the "
                                 f"difference step or its side ({np.max(np.abs(forward - backward)):.2g}): the "
                                 "expressions are not smooth at the operating point (a kink or a branch); choose "
                                 "another point")
        columns.append(fine)
    return np.array(columns).T.reshape(-1, z0.size)


def linearise(f, h, x0, u0, p, t0: float = 0.0, where: str = "operating point") -> Linearisation:
    """The checked linearisation of ``f(t, x, u, p)`` (n) and ``h(t, x, u, p)`` (q) at ``(t0, x0, u0)``."""
    x0, u0, p = (np.asarray(v, dtype=float) for v in (x0, u0, p))
    f0 = np.asarray(f(t0, x0, u0, p), dtype=float)
    y0 = np.asarray(h(t0, x0, u0, p), dtype=float)
    if not (np.all(np.isfinite(f0)) and np.all(np.isfinite(y0))):
        raise ParameterError(f"{where}: f or h is not finite at the operating point")
    A = _jacobian(lambda x: f(t0, x, u0, p), x0, where, "x")
    C = _jacobian(lambda x: h(t0, x, u0, p), x0, where, "x")
    if u0.size:
        B = _jacobian(lambda u: f(t0, x0, u, p), u0, where, "u")
        D = _jacobian(lambda u: h(t0, x0, u, p), u0, where, "u")
    else:
        B, D = np.zeros((x0.size, 0)), np.zeros((y0.size, 0))
    return Linearisation(A.reshape(x0.size, x0.size), B.reshape(x0.size, u0.size), C.reshape(y0.size, x0.size),
                         D.reshape(y0.size, u0.size), f0, y0)
