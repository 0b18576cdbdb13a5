r"""Stepping helpers shared by the LTV plant and observer of paper 001.

* :func:`time_function` -- check the user's ``A(t)``, ``L(t)``, ``C(t)`` once, naming the parameter
  (``f`` and ``C``: :mod:`observers.ltv.model`).
* :class:`PolynomialInputs` -- the inputs inside a communication step as the polynomial through
  the last ``degree + 1`` communication points (order ``degree + 1``) instead of the chord.
* :func:`rk4_linear` -- RK4 for ``S' = A0(t) S + G(t)`` with values inside the step (dense output).
* :func:`resolved_output` -- the output inside a step with the fast part that ``m f(y)`` drives
  resolved (``f_correction``), and :class:`IntegralSamples`, the samples of ``int f(y)`` it needs.

Why polynomials
---------------
With linear interpolation of ``y`` across a step (Gauss-Seidel, ``<port>_interpolation = 2``)
the observer's filters see ``y`` off by ``s (h - s) y''/2``, on average ``h^2 y''/12``, and the
regression (7) is sensitive to it through its weakly excited directions.  Measured against the
monolithic reference (largest ``|theta_hat - theta_ref|``): bounded example at h = 1e-3, chord
9.7e-6, parabola 4.7e-7; at h = 1e-2 (with the master's start-up ramp) parabola 2.2e-5, cubic
1.7e-6, quartic 1.3e-7; the paper's example at h = 1e-4 (``|y''|`` ~ 3e4 by 15 s), chord 4.7e-4,
parabola 3.0e-5 (its fast wiggle gains nothing from a higher degree).  The polynomial through
``y(t_(k-d+1)), ..., y(t_k) = y(t)`` and ``y(t + h)`` (the segment's end) is exact for polynomials
of degree ``d``; its monomial coefficients in ``s = t' - t`` come from the inverse Vandermonde
matrix of the nodes in units of ``h``, cached (a fixed step has one node pattern).

The history is used only when the segment continues the previous one (its start equals the
previous segment's end): that is the case when the master interpolates (``2``), the producer
stepped before this block.  With hold (``0``) or extrapolation (``1``) the segment does not
continue and is used as it is -- the reconstruction never makes those modes worse.  Noisy
samples want a low degree: the polynomial amplifies noise as well as it follows the signal.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..block import MAGNITUDE_BOUND
from ..checks import ParameterError, SignalError

__all__ = ["time_function", "InputPolynomial", "PolynomialInputs", "rk4_linear",
           "IntegralSamples", "resolved_output", "substep_points", "SUBSTEP_POINTS", "PHI_LIMIT"]


def time_function(name: str, function: Callable, shape: tuple[int, ...]) -> Callable:
    """Check that ``function(t)`` returns finite values of ``shape`` (at ``t = 0``); return it."""
    if not callable(function):
        raise ParameterError(f"{name}: expected a function of time, got {function!r}")
    try:
        value = np.asarray(function(0.0), dtype=float)
    except Exception as exc:
        raise ParameterError(f"{name}: calling {name}(0.0) failed: {type(exc).__name__}: {exc}") from None
    if value.shape != shape:
        raise ParameterError(f"{name}: {name}(t) must return shape {shape}, got {value.shape} at t = 0")
    if not np.all(np.isfinite(value)):
        raise ParameterError(f"{name}: {name}(0) is not finite: {value.tolist()}")
    return function


@dataclass(frozen=True)
class InputPolynomial:
    """A scalar input over one step: ``value(s) = sum_k coefficients[k] s^k``, ``0 <= s <= h``."""

    coefficients: tuple[float, ...]
    h: float

    @property
    def degree(self) -> int:
        return len(self.coefficients) - 1

    @property
    def start(self) -> float:
        return self.coefficients[0]

    def at(self, s: float) -> float:
        value = 0.0
        for c in reversed(self.coefficients):
            value = value * s + c
        return value

    def max_rate(self) -> float:
        """A bound on ``|d value / ds|`` over ``[0, h]``: ``sum_k k |c_k| h^(k-1)``."""
        return sum(k * abs(c) * self.h ** (k - 1) for k, c in enumerate(self.coefficients) if k)


@lru_cache(maxsize=64)
def _monomial_map(nodes: tuple[float, ...]) -> tuple[tuple[float, ...], ...]:
    """Rows taking the values at ``nodes`` (in units of the step) to monomial coefficients."""
    return tuple(map(tuple, np.linalg.inv(np.vander(np.array(nodes), increasing=True)).tolist()))


class PolynomialInputs:
    """Each block input over a step as the polynomial through the last ``degree + 1`` samples.

    The samples are the communication points of consecutive segments that continue each other
    (the master interpolates: every segment starts where the previous one ended, and its end is
    the producer's output at ``t + h``).  A segment that does not continue the previous one (hold,
    extrapolation, the first step) is used as it is and restarts the history.  Immutable: a
    block's state holds one, and :meth:`step` returns the inputs over a step together with the
    history after it, which the block rebinds once its step has succeeded.  Its samples are
    checked as they come (finite, within ``MAGNITUDE_BOUND``), so a rollback point shares it
    (``immutable``, :mod:`observers.state`).
    """

    immutable = True

    def __init__(self, degree: int = 2, samples: dict | None = None):
        if int(degree) != degree or not 1 <= degree <= 5:
            raise ParameterError(f"input_degree: expected an integer from 1 to 5, got {degree!r}")
        self.degree = int(degree)
        #: name -> (count, times, values): the last ``count`` of ``degree + 1`` entries are the samples.
        #: A fixed layout (zeros in front), so that an FMU state restores into any history of the block.
        self.samples: dict[str, tuple[int, tuple[float, ...], tuple[float, ...]]] = samples or {}

    def history(self, name: str) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """The samples of input ``name``: ``(times, values)``, oldest first."""
        count, times, values = self.samples.get(name, (0, (), ()))
        return times[len(times) - count:], values[len(values) - count:]

    def step(self, t: float, h: float, segments) -> tuple[dict[str, InputPolynomial], "PolynomialInputs"]:
        """The inputs over ``[t, t + h]`` and the history after the step (this object is unchanged);
        :class:`~observers.checks.SignalError` on NaN/inf or beyond ``MAGNITUDE_BOUND``."""
        polynomials, samples = {}, dict(self.samples)
        for name, segment in segments.items():
            start, slope = float(segment.start[0]), float(segment.slope[0])
            end = start + h * slope
            if not (abs(start) <= MAGNITUDE_BOUND and abs(end) <= MAGNITUDE_BOUND and math.isfinite(slope)
                    and math.isfinite(t + h)):
                raise SignalError(f"input {name}: not finite or beyond {MAGNITUDE_BOUND:g} "
                                  f"({start}, slope {slope}, at t = {t} over h = {h})")
            times, values = self._continued(name, t, start)
            times, values = times[-self.degree:], values[-self.degree:]
            nodes = tuple(round((time - t) / h, 12) for time in times) + (1.0,)
            if len(set(nodes)) < len(nodes):     # a step so long that the samples coincide at its scale: restart
                times, values = (t,), (start,)
            if len(times) == 1:
                polynomials[name] = InputPolynomial((start, slope), h)
            else:
                rows = _monomial_map(nodes)
                points = values + (end,)
                polynomials[name] = InputPolynomial(tuple(
                    sum(m * v for m, v in zip(row, points)) / h ** k for k, row in enumerate(rows)), h)
            padding = (0.0,) * (self.degree - len(times))
            samples[name] = (len(times) + 1, padding + times + (t + h,), padding + values + (end,))
        return polynomials, PolynomialInputs(self.degree, samples)

    def _continued(self, name: str, t: float, start: float) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """The samples before ``t`` that a segment starting at ``start`` continues, ``t`` included."""
        times, values = self.history(name)
        continues = bool(times) and (abs(times[-1] - t) <= 1e-9 * max(1.0, abs(t))
                                     and abs(values[-1] - start) <= 1e-12 * max(1.0, abs(start), abs(values[-1])))
        return (times, values) if continues else ((t,), (start,))


def rk4_linear(S: np.ndarray, dt: float, start, middle, end, nodes=(0.5,)):
    """One RK4 step of ``S' = A0(t) S + G(t)``; ``start``, ``middle``, ``end`` are ``(A0, G)``
    at ``t``, ``t + dt/2``, ``t + dt`` (evaluated once each, the end reused by the next step).

    Returns ``S(t + dt)`` and the list of ``S(t + theta dt)`` for ``theta`` in ``nodes``, from
    RK4's third-order dense output ``S + dt sum_i b_i(theta) k_i`` with
    ``b1 = theta - 3 theta^2/2 + 2 theta^3/3``, ``b2 = b3 = theta^2 - 2 theta^3/3``,
    ``b4 = -theta^2/2 + 2 theta^3/3``.
    """
    (A_0, G_0), (A_m, G_m), (A_1, G_1) = start, middle, end
    k1 = A_0 @ S + G_0
    k2 = A_m @ (S + 0.5 * dt * k1) + G_m
    k3 = A_m @ (S + 0.5 * dt * k2) + G_m
    k4 = A_1 @ (S + dt * k3) + G_1
    S_end = S + dt / 6.0 * (k1 + 2.0 * (k2 + k3) + k4)
    inside = []
    for th in nodes:
        b1, b23, b4 = dense_weights(th)
        inside.append(S + dt * (b1 * k1 + b23 * (k2 + k3) + b4 * k4))
    return S_end, inside


@lru_cache(maxsize=16)
def dense_weights(th: float) -> tuple[float, float, float]:
    """RK4's third-order dense output at ``theta``: ``(b1, b2 = b3, b4)``."""
    return (th - 1.5 * th ** 2 + 2.0 / 3.0 * th ** 3, th ** 2 - 2.0 / 3.0 * th ** 3,
            -0.5 * th ** 2 + 2.0 / 3.0 * th ** 3)


#: the filter transition matrix Phi growing beyond this means A0 is not stable
PHI_LIMIT = 1e8

#: where a filter sub-step needs ``y`` (fractions of the sub-step): RK4's midpoint and end, then the
#: two Gauss-Legendre nodes of the regression
SUBSTEP_POINTS = (0.5, 1.0, 0.5 - 3.0 ** 0.5 / 6.0, 0.5 + 3.0 ** 0.5 / 6.0)


def substep_points(y: InputPolynomial, count: int) -> list[tuple[float, ...]]:
    """The polynomial ``y`` at :data:`SUBSTEP_POINTS` of each of ``count`` equal sub-steps."""
    dt = y.h / count
    return [tuple(y.at((i + th) * dt) for th in SUBSTEP_POINTS) for i in range(count)]


class IntegralSamples:
    """The running integral ``I = int f(y) dt`` at the last ``degree + 1`` communication points.

    Immutable, with the fixed layout of :class:`PolynomialInputs`' samples ``(count, times,
    values)`` (zeros in front), so that an FMU state restores into any history.  Only differences
    of ``I`` matter (a polynomial reproduces constants): a restarted history starts at 0.  Its
    samples are checked as they come, as :class:`PolynomialInputs`' are.
    """

    immutable = True

    def __init__(self, degree: int, samples: tuple | None = None):
        self.samples = samples or (0, (0.0,) * (degree + 1), (0.0,) * (degree + 1))

    def at(self, times) -> list[float] | None:
        """``I(time) - I(times[-1])`` for ``times`` (oldest first, ``times[-1]`` the step's start);
        None when a time is not a sample (the history restarted)."""
        count, stored, values = self.samples
        known = {round(time, 12): value for time, value in zip(stored[len(stored) - count:],
                                                                values[len(values) - count:])}
        found = [known.get(round(time, 12)) for time in times]
        if any(value is None for value in found):
            return None
        return [value - found[-1] for value in found]

    def after(self, t: float, h: float, change: float) -> "IntegralSamples":
        """The samples after a step ``[t, t + h]`` over which ``I`` changed by ``change``."""
        count, times, values = self.samples
        size = len(times)
        times, values = list(times[size - count:]), list(values[size - count:])
        if not (times and abs(times[-1] - t) <= 1e-9 * max(1.0, abs(t))):
            times, values = [t], [0.0]
        if not (abs(values[-1] + change) <= MAGNITUDE_BOUND and math.isfinite(t + h)):
            raise SignalError(f"int f(y) over the step to t = {t + h}: {values[-1] + change} is not finite "
                              f"or beyond {MAGNITUDE_BOUND:g}")
        times, values = (times + [t + h])[-size:], (values + [values[-1] + change])[-size:]
        padding = (0.0,) * (size - len(times))
        return IntegralSamples(size - 1, (len(times), padding + tuple(times), padding + tuple(values)))


def resolved_output(f: Callable, y: InputPolynomial, times: tuple[float, ...], past: list[float] | None,
                    mu: float, count: int) -> tuple[list[tuple[float, ...]], float]:
    r"""``y`` at :data:`SUBSTEP_POINTS` of each of ``count`` equal sub-steps, and ``int f(y)`` over the step.

    The output of plant (1) obeys ``y' = C^T (A x + k y + b u) + mu f(y)``, ``mu = C^T m``: with
    ``I = int f(y) dt``, ``y - mu I`` is as smooth as the state, while ``y`` itself wiggles at
    ``|y'|`` rad/s with amplitude ``|mu| / |y'|`` -- more than a polynomial through samples 1 ms
    apart can follow once ``|y'|`` is in the hundreds.  So the polynomial interpolates ``y - mu I``
    (``p`` and ``Pi I``: the polynomials through the samples of ``y`` at ``times`` and of ``I``)
    and inside the step

    .. math:: y(s) = p(s) + \mu\,(J(s) - \Pi J(s)), \qquad J' = f(y), \quad J(0) = 0,

    ``J = I - I(t)``, integrated by RK4 on the sub-steps (its dense output gives the points inside
    them).  ``Pi J`` depends on ``J(h)`` itself: one pass with ``J(h)`` from ``f(p)`` and one with
    the result (the map contracts by ``|mu| h``).  ``y`` still passes through every sample; with
    ``mu = 0`` (or ``past`` None: no samples of ``I``) it is the polynomial ``p``.

    ``past`` are ``J`` at ``times[:-1]`` (``times[-1]`` is the step's end).  The exact ``mu`` is
    ``C^T m``; the observer passes its estimate (the error it leaves is second order: the wiggle
    of the other states).
    """
    h = y.h
    dt = h / count
    gauss = SUBSTEP_POINTS[2:]
    J_end = sum(0.5 * dt * f(y.at((i + node) * dt)) for i in range(count) for node in gauss)
    if past is None or not mu:
        return substep_points(y, count), J_end
    rows = _monomial_map(tuple(round((time - times[-2]) / h, 12) for time in times))

    def without_fast_part(J_end):                      # q = p - mu Pi J, so that y = q + mu J
        values = list(past) + [J_end]
        coefficients = list(y.coefficients) + [0.0] * (len(rows) - len(y.coefficients))
        for k, row in enumerate(rows):
            coefficients[k] -= mu * sum(m * v for m, v in zip(row, values)) / h ** k
        return InputPolynomial(tuple(coefficients), h)

    for _ in range(2):                                 # J(h) from f(p), then from the first pass
        J_end, J_points = _rk4_integral(f, without_fast_part(J_end), mu, count, dt)
    q = without_fast_part(J_end)                       # Pi J through the final J(h): y(h) is the sample
    return [tuple(q.at((i + th) * dt) + mu * J for th, J in zip(SUBSTEP_POINTS, J_i))
            for i, J_i in enumerate(J_points)], J_end


def _rk4_integral(f: Callable, q: InputPolynomial, mu: float, count: int, dt: float):
    """RK4 for ``J' = f(q(s) + mu J)``, ``J(0) = 0``: ``J(h)`` and ``J`` at :data:`SUBSTEP_POINTS`."""
    J, points = 0.0, []
    for i in range(count):
        s = i * dt
        middle = q.at(s + 0.5 * dt)
        k1 = f(q.at(s) + mu * J)
        k2 = f(middle + mu * (J + 0.5 * dt * k1))
        k3 = f(middle + mu * (J + 0.5 * dt * k2))
        k4 = f(q.at(s + dt) + mu * (J + dt * k3))
        points.append(tuple(J + dt * (b1 * k1 + b23 * (k2 + k3) + b4 * k4)
                            for b1, b23, b4 in map(dense_weights, SUBSTEP_POINTS)))
        J = points[-1][1]                              # theta = 1: RK4's own step
    return J, points
