r"""Dynamic regressor extension: from ``Y = Phi theta`` (m rows) to a square ``Y_e = Phi_e theta``.

First stage of DREM (Aranovskiy et al. 2017; papers 000 eq. (18), 003 before
eq. (11), 004 eq. (6)).  Each extension applies operators that commute with
the regression (linear filters, delays) to the measured ``Y`` and ``Phi`` and
stacks the results into ``p`` rows, so that ``Y_e = Phi_e theta`` holds
exactly when the filter initial conditions are zero.

Every extension has the same small interface, used by
:class:`~observers.estimation.DREM` and usable on its own:

``p``
    number of parameters (columns of ``Phi``, rows of ``Phi_e``);
``rows``
    rows ``m`` of the regression it expects (``None``: any);
``extend(Y, Phi) -> (Y_e, Phi_e)``
    the extended regression at the *start* of the step, ``Y_e`` of shape
    ``(p,)`` and ``Phi_e`` of shape ``(p, p)``; does not change the state;
``advance(Y, Phi, dt)``
    move the internal state to the end of the step, ``Y``, ``Phi`` held;
``reset()``
    zero the internal state.

``Y`` and ``Phi`` are float arrays of shape ``(m,)`` and ``(m, p)``, finite
(the estimators check them before calling; ``extend`` checks the shape only).
Continuous filters are advanced with the exact zero-order-hold solution
(:func:`~observers.estimation.exponential.held_input_lowpass`): a held
regression stays exactly a regression after filtering, with no
discretisation error.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from obsfmu.observers.checks import ParameterError, as_vector, require_positive

from ._validation import dimension
from .exponential import held_input_lowpass

__all__ = ["KreisselmeierExtension", "FilterBankExtension", "DelayExtension"]


def _check_shape(Phi: np.ndarray, rows: int | None, p: int) -> None:
    if Phi.ndim != 2 or Phi.shape[1] != p or (rows is not None and Phi.shape[0] != rows):
        expected = f"({'m' if rows is None else rows}, {p})"
        raise ParameterError(f"phi: expected shape {expected}, got {Phi.shape}")


class KreisselmeierExtension:
    r"""Kreisselmeier extension: filter ``Phi^T Y = Phi^T Phi theta`` with ``1/(p + a)``.

    .. math:: \dot\Phi_e = -a \Phi_e + \Phi^T\Phi, \qquad \dot Y_e = -a Y_e + \Phi^T Y,
              \qquad \Phi_e(0) = 0,\; Y_e(0) = 0 .

    Parameters
    ----------
    p : int
        Number of parameters.
    a : float
        Forgetting rate ``>= 0``.  ``a = 0`` is the integral extension
        ``Phi_e = int Phi^T Phi``, which never forgets: once the regressor
        has been exciting on some interval, ``Delta`` stays away from zero
        (use ``normalize=True`` in the mixing, ``Phi_e`` grows).

    Notes
    -----
    Accepts any number of regression rows.  ``Phi_e`` is zero at ``t = 0``,
    so the first step has ``Delta = 0``.
    """

    rows = None
    not_state = ("p", "a")        # fixed settings (observers.state); the filter states are the state

    def __init__(self, p: int, a: float):
        self.p = dimension("p", p)
        self.a = require_positive("a", a, allow_zero=True)
        self.reset()

    def reset(self) -> None:
        self.Y_e = np.zeros(self.p)
        self.Phi_e = np.zeros((self.p, self.p))

    def extend(self, Y, Phi):
        _check_shape(Phi, None, self.p)
        return self.Y_e, self.Phi_e

    def advance(self, Y, Phi, dt: float) -> None:
        self.Y_e = held_input_lowpass(self.Y_e, Phi.T @ Y, self.a, dt)
        self.Phi_e = held_input_lowpass(self.Phi_e, Phi.T @ Phi, self.a, dt)


class FilterBankExtension:
    r"""Extension by a bank of stable LTI filters ``H_i = a_i / (p + a_i)``.

    .. math::
        Y_e = \begin{bmatrix} Y \\ H_1[Y] \\ \vdots \\ H_n[Y] \end{bmatrix}, \qquad
        \Phi_e = \begin{bmatrix} \Phi \\ H_1[\Phi] \\ \vdots \\ H_n[\Phi] \end{bmatrix},
        \qquad \dot x_i = a_i (u - x_i),\; x_i(0) = 0 .

    Parameters
    ----------
    rates : array_like
        Distinct filter rates ``a_i > 0``.
    rows : int, default 1
        Rows ``m`` of the regression (1 for ``y = phi^T theta``).
    keep_original : bool, default True
        Put the unfiltered regression on top (paper 003, DREM of Aranovskiy
        et al.); ``False`` stacks only the ``n`` filtered copies (paper 004,
        eq. (6), ``N`` values ``a_i``).

    Attributes
    ----------
    p : int
        ``rows * (n + keep_original)``, the number of parameters it serves.
    """

    not_state = ("rates", "rows", "keep_original", "p")

    def __init__(self, rates, rows: int = 1, keep_original: bool = True):
        self.rates = as_vector("rates", rates)
        if np.any(self.rates <= 0):
            raise ParameterError(f"rates: every filter rate must be > 0, got {self.rates.tolist()}")
        if np.unique(self.rates).size != self.rates.size:
            raise ParameterError(f"rates: must be distinct (equal filters give Delta = 0), got {self.rates.tolist()}")
        self.rows = dimension("rows", rows)
        self.keep_original = bool(keep_original)
        self.p = self.rows * (self.rates.size + int(self.keep_original))
        self.reset()

    def reset(self) -> None:
        n = self.rates.size
        self.filtered_Y = np.zeros((n, self.rows))
        self.filtered_Phi = np.zeros((n, self.rows, self.p))

    def extend(self, Y, Phi):
        _check_shape(Phi, self.rows, self.p)
        Y_e = self.filtered_Y.reshape(-1)
        Phi_e = self.filtered_Phi.reshape(-1, self.p)
        if self.keep_original:
            Y_e = np.concatenate((Y, Y_e))
            Phi_e = np.concatenate((Phi, Phi_e))
        return Y_e, Phi_e

    def advance(self, Y, Phi, dt: float) -> None:
        a = self.rates[:, None]
        self.filtered_Y = held_input_lowpass(self.filtered_Y, a * Y, a, dt)
        a = a[:, :, None]
        self.filtered_Phi = held_input_lowpass(self.filtered_Phi, a * Phi, a, dt)


class DelayExtension:
    r"""Extension by pure delays counted in samples (paper 000, eq. (18)).

    .. math::
        Y_e(k) = \begin{bmatrix} Y(k) \\ Y(k - v_1) \\ \vdots \end{bmatrix}, \qquad
        \Phi_e(k) = \begin{bmatrix} \Phi(k) \\ \Phi(k - v_1) \\ \vdots \end{bmatrix}

    Parameters
    ----------
    delays : sequence of int
        Distinct delays ``v_i >= 1`` in samples (one sample = one call of
        :meth:`advance`; with a constant step ``dt`` the delay is
        ``v_i dt`` seconds).
    rows : int, default 1
        Rows ``m`` of the regression.

    Notes
    -----
    Samples before the start are zero, so ``Delta = 0`` until
    ``max(delays)`` samples have been seen.
    """

    not_state = ("delays", "rows", "p")

    def __init__(self, delays, rows: int = 1):
        values = as_vector("delays", delays)
        if np.any(values < 1) or np.any(values != np.round(values)):
            raise ParameterError(f"delays: expected integers >= 1 (samples), got {values.tolist()}")
        if np.unique(values).size != values.size:
            raise ParameterError(f"delays: must be distinct, got {values.tolist()}")
        self.delays = [int(v) for v in values]
        self.rows = dimension("rows", rows)
        self.p = self.rows * (len(self.delays) + 1)
        self.reset()

    def reset(self) -> None:
        zero = (np.zeros(self.rows), np.zeros((self.rows, self.p)))
        depth = max(self.delays, default=1)
        self.history = deque([zero] * depth, maxlen=depth)

    def extend(self, Y, Phi):
        _check_shape(Phi, self.rows, self.p)
        past = [self.history[-v] for v in self.delays]
        Y_e = np.concatenate([Y] + [sample[0] for sample in past])
        Phi_e = np.concatenate([Phi] + [sample[1] for sample in past])
        return Y_e, Phi_e

    def advance(self, Y, Phi, dt: float = 1.0) -> None:
        self.history.append((np.array(Y, dtype=float), np.array(Phi, dtype=float)))
