"""Standard characteristic polynomials for modal (pole-placement) design.

A standard form fixes the *shape* of a transient; one time constant fixes its
speed.  Paper 002 (ship course stabilisation) uses the binomial form

    D(s) = (T s + 1)^n,    T = t_settle / (3 n),                    (paper 002, eq. (9))

e.g. ``n = 2, t_settle = 0.3 s -> T = 0.05 s -> D(s) = s^2 + 40 s + 400``.
The Butterworth form places the poles evenly on a half circle of radius
``omega0``; its ``omega0`` is chosen so that the 5 % settling time of the
normalised step response equals ``t_settle`` (computed, not tabulated).

All functions return *monic* coefficient arrays, highest power first
(``numpy.polyval`` order), or the roots of those polynomials.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from .checks import ParameterError, require_positive

__all__ = [
    "binomial",
    "butterworth",
    "butterworth_omega",
    "butterworth_poles",
    "butterworth_settling",
    "settling_time",
    "standard_poles",
    "FORMS",
]


def _order(n) -> int:
    if int(n) != n or n < 1:
        raise ParameterError(f"n: the polynomial order must be a positive integer, got {n!r}")
    return int(n)


def binomial(n: int, t_settle: float) -> np.ndarray:
    """Monic coefficients of the binomial form ``(T s + 1)^n / T^n``.

    Parameters
    ----------
    n : int
        Order of the polynomial (the system order).
    t_settle : float
        Desired settling time in seconds; ``T = t_settle / (3 n)`` (paper 002, eq. (9)).

    Returns
    -------
    numpy.ndarray
        ``[1, a_{n-1}, ..., a_0]`` of ``(s + 1/T)^n``.

    Examples
    --------
    >>> binomial(2, 0.3)
    array([  1.,  40., 400.])
    """
    n = _order(n)
    T = require_positive("t_settle", t_settle) / (3 * n)
    return np.poly(np.full(n, -1.0 / T))


def butterworth(n: int, omega0: float) -> np.ndarray:
    """Monic Butterworth polynomial of order ``n`` and radius ``omega0`` (rad/s).

    The roots are ``omega0 * exp(i pi (2k + n - 1) / (2n))``, ``k = 1..n``.
    """
    n = _order(n)
    omega0 = require_positive("omega0", omega0)
    k = np.arange(1, n + 1)
    angle = np.pi * (2 * k + n - 1) / (2 * n)
    roots = omega0 * (np.cos(angle) + 1j * np.sin(angle))
    return np.real(np.poly(roots))


def settling_time(coefficients, band: float = 0.05) -> float:
    """5 % (``band``) settling time of the unit-DC-gain step response ``a_0 / D(s)``.

    Computed from a dense step response of the stable polynomial ``D``.
    """
    den = np.asarray(coefficients, dtype=float)
    if np.any(np.roots(den).real >= 0):
        raise ParameterError("coefficients: polynomial is not Hurwitz, no settling time")
    slowest = -np.max(np.roots(den).real)
    horizon = 40.0 / slowest
    t = np.linspace(0.0, horizon, 40001)
    from scipy import signal   # here: scipy.signal costs ~0.5 s to import
    _, response = signal.step(signal.lti([den[-1]], den), T=t)
    outside = np.nonzero(np.abs(response - 1.0) > band)[0]
    return float(t[outside[-1] + 1]) if outside.size else 0.0


@lru_cache(maxsize=None)
def butterworth_settling(n: int) -> float:
    """The 5 % settling time of the Butterworth form of order ``n`` and radius 1 (its step response: scipy)."""
    return settling_time(butterworth(_order(n), 1.0))


def butterworth_omega(n: int, t_settle: float, normalised: float | None = None) -> float:
    """Radius ``omega0`` for which the Butterworth form settles (5 %) in ``t_settle``; ``normalised``: its
    :func:`butterworth_settling` computed before (an FMU designing at initialisation has no scipy)."""
    normalised = butterworth_settling(_order(n)) if normalised is None else normalised
    return normalised / require_positive("t_settle", t_settle)


def butterworth_poles(n: int, omega0: float) -> np.ndarray:
    """The roots of :func:`butterworth`, ``omega0 exp(i pi (2k + n - 1) / (2n))``, from their real and imaginary
    parts (no complex function: the C runtime of wine 8 lacks them); a real root's imaginary part is exactly 0."""
    n = _order(n)
    angle = np.pi * (2 * np.arange(1, n // 2 + 1) + n - 1) / (2 * n)      # the upper half plane's, k <= n / 2
    real, imaginary = omega0 * np.cos(angle), omega0 * np.sin(angle)
    pairs = [complex(r, i) for r, i in zip(real, imaginary)] + [complex(r, -i) for r, i in zip(real, imaginary)]
    return np.array(pairs + ([complex(-omega0, 0.0)] if n % 2 else []))       # exact conjugates, and -omega0


FORMS = ("binomial", "butterworth")


def standard_poles(n: int, t_settle: float, form: str = "binomial", normalised: float | None = None) -> np.ndarray:
    """Roots of the standard ``form`` of order ``n`` that settles in ``t_settle`` seconds.

    ``form`` is ``"binomial"`` (paper 002: ``T = t_settle / (3n)``, an n-fold pole at
    ``-1/T``) or ``"butterworth"`` (5 % settling time matched numerically; ``normalised``: its
    :func:`butterworth_settling`, when computed before).
    """
    if form == "binomial":
        n = _order(n)
        return np.full(n, -3.0 * n / require_positive("t_settle", t_settle))
    if form == "butterworth":
        return butterworth_poles(n, butterworth_omega(n, t_settle, normalised))
    raise ParameterError(f"form: unknown standard form {form!r}; choose one of {FORMS}")
