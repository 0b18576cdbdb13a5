r"""Exact steps of linear ODEs whose input is held over the step.

Every continuous law of this package is linear in its own state once the
measured signals are held over a step of length ``dt`` (zero-order hold), so
it is advanced with the exact solution instead of an explicit scheme.  The
one special function needed is

.. math:: \varphi_1(x) = \frac{1 - e^{-x}}{x}, \qquad \varphi_1(0) = 1,

because ``x' = -a x + u`` with ``u`` held gives
``x(t + dt) = x(t) + dt * phi1(a dt) * (u - a x(t))``.  Written with
``expm1`` this is accurate for tiny ``a dt`` (no cancellation) and stable for
huge ``a dt`` (``phi1 -> 1/(a dt)``, the step lands on the equilibrium
``u / a``), so gains such as ``gamma Delta^2 = 1e10 1/s`` at ``dt = 1e-3 s``
are no problem.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["phi1", "phi1_symmetric", "held_input_lowpass"]


def phi1(x):
    r"""Return :math:`\varphi_1(x) = (1 - e^{-x}) / x` (elementwise), with :math:`\varphi_1(0) = 1`.

    Parameters
    ----------
    x : float or array_like
        ``x = rate * dt >= 0`` in this package (negative ``x`` works down to
        about -700, where ``e^{-x}`` overflows).

    Returns
    -------
    float or ndarray
        Same shape as ``x``.  Relative accuracy is a few ulp for every ``x``,
        including ``x`` near 0 (``expm1``) and ``x -> inf`` (``1/x``).
    """
    if np.ndim(x) == 0:
        x = float(x)
        return 1.0 if x == 0.0 else -math.expm1(-x) / x
    x = np.asarray(x, dtype=float)
    return np.divide(-np.expm1(-x), x, out=np.ones_like(x), where=x != 0.0)


def phi1_symmetric(S: np.ndarray) -> np.ndarray:
    r"""Return the matrix function :math:`\varphi_1(S) = S^{-1}(I - e^{-S})` of a symmetric ``S``.

    Computed from the eigendecomposition ``S = V diag(lambda) V^T`` as
    ``V diag(phi1(lambda)) V^T``, which needs no inverse and is exact for a
    singular ``S`` (``phi1(0) = 1``).
    """
    if S.shape == (1, 1):
        return np.array([[phi1(S[0, 0])]])
    eigenvalues, vectors = np.linalg.eigh(S)
    return (vectors * phi1(eigenvalues)) @ vectors.T


def held_input_lowpass(state, u, rate, dt: float):
    r"""Exact step of the low-pass filter ``x' = -a x + u`` (transfer ``1/(p + a)``) for ``u`` held.

    .. math:: x(t + dt) = e^{-a\,dt} x(t) + dt\,\varphi_1(a\,dt)\,u

    Parameters
    ----------
    state, u : float or ndarray
        Filter state and held input (broadcast together).
    rate : float or ndarray
        ``a >= 0``; ``a = 0`` is the integrator ``x' = u``.  An array of rates
        must broadcast against ``state`` (a bank of filters).
    dt : float
        Step length.

    Notes
    -----
    The filter ``a/(p + a)`` is this one with input ``a u``.  The formula is
    the zero-order-hold discretisation, exact for a held input: applying
    the same filter to both sides of a regression ``y = phi^T theta`` with
    held ``y, phi`` keeps the filtered regression exact at every sample.
    """
    x = np.asarray(rate, dtype=float) * dt
    return np.exp(-x) * state + dt * phi1(x) * u
