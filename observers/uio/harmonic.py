r"""Stage 3 of paper 003: the amplitudes of the disturbance, eqs. (20)-(23).

Once ``xi(0)`` and the frequencies are known, (20) is a linear regression

.. math:: \bar f(t) = q(t) - s^T(t)\,\xi(0)
          = \sum_k a_{k1} \sin\omega_k t + a_{k2}\cos\omega_k t = \Phi^T(t)\,a ,

whose sinusoid is the *steady state* of ``f_bar = F_2[f]``,
``F_2 = lambda^r / (p + lambda)^r``: the amplitudes found are those of the
filtered disturbance.  (23) undoes the filter,
``f = ((p + lambda)^r / lambda^r) f_bar``, with the derivatives of the
sinusoid known in closed form: for one harmonic,
``d/dt (a_1 sin wt + a_2 cos wt) = Phi^T D a`` with ``D = w [[0, -1], [1, 0]]``, so

.. math:: f(t) = \Phi^T(t)\,(I + D/\lambda)^r\, a .
"""

from __future__ import annotations

import numpy as np

__all__ = ["harmonic_regressor", "undo_filter", "disturbance_amplitudes"]


def harmonic_regressor(t: float, omegas: np.ndarray) -> np.ndarray:
    """``Phi(t) = [sin w_1 t, cos w_1 t, sin w_2 t, cos w_2 t, ...]`` of (20)."""
    phase = np.asarray(omegas, dtype=float) * t
    return np.column_stack([np.sin(phase), np.cos(phase)]).ravel()


def undo_filter(a: np.ndarray, omegas: np.ndarray, lam: float, order: int) -> np.ndarray:
    r"""Amplitudes of ``f`` from those of ``f_bar = lambda^r/(p + lambda)^r [f]``, eq. (23).

    Parameters
    ----------
    a : (2N,) ndarray
        ``[a_11, a_12, a_21, a_22, ...]`` of ``f_bar`` (sine, cosine per harmonic).
    omegas : (N,) ndarray
    lam : float
    order : int
        ``r``, the order of the filter.

    Returns
    -------
    (2N,) ndarray
        The amplitudes ``(I + D_k / lambda)^r a_k`` of ``f``.
    """
    a = np.asarray(a, dtype=float).reshape(-1, 2)
    result = np.empty_like(a)
    for k, (omega, amplitudes) in enumerate(zip(omegas, a)):
        step = np.eye(2) + omega / lam * np.array([[0.0, -1.0], [1.0, 0.0]])
        result[k] = np.linalg.matrix_power(step, order) @ amplitudes
    return result.ravel()


def disturbance_amplitudes(b: np.ndarray) -> np.ndarray:
    """Amplitude ``sqrt(b_1^2 + b_2^2)`` of each harmonic ``b_1 sin + b_2 cos``."""
    return np.hypot(*np.asarray(b, dtype=float).reshape(-1, 2).T)
