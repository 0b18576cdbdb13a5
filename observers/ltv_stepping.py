r"""Stepping helpers shared by the LTV plant and observer of paper 001.

* :func:`time_function`, :func:`output_function` -- check the user's ``A(t)``, ``L(t)``,
  ``f(y)`` once, naming the parameter.
* :class:`QuadraticInputs` -- the inputs inside a communication step as parabolas through the
  last three communication points (third order) instead of the chord (second order).
* :func:`rk4_linear` -- RK4 for ``S' = A0(t) S + G(t)`` with values inside the step (dense output).

Why parabolas
-------------
With linear interpolation of ``y`` across a step (Gauss-Seidel, ``<port>_interpolation = 2``)
the observer's filters see ``y`` off by ``s (h - s) y''/2``, on average ``h^2 y''/12``, and the
regression (7) is sensitive to it through its weakly excited directions.  Measured against the
monolithic reference (largest ``|theta_hat - theta_ref|``): bounded example at h = 1e-3, chord
9.7e-6, parabola 4.7e-7; the paper's example at h = 1e-4 (``|y''|`` ~ 3e4 by 15 s), chord 4.7e-4,
parabola 3.0e-5.  The parabola through ``y(t - h_prev)``, ``y(t)``, ``y(t + h)``,

.. math:: y(t + s) = y(t) + s\,d + c\,s (s - h), \qquad
          c = \frac{d - d_{prev}}{h + h_{prev}} ,

(``d``, ``d_prev`` the slopes of this and the previous segment) is exact for quadratics.

The curvature ``c`` is used only when the segment continues the previous one (its start equals
the previous segment's end): that is the case when the master interpolates (``2``), the producer
stepped before this block.  With hold (``0``) or extrapolation (``1``) a continuing segment has
the previous slope, so ``c = 0`` and nothing changes -- the reconstruction never makes those
modes worse.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .block import Segment
from .checks import ParameterError, finite_signal

__all__ = ["time_function", "output_function", "Parabola", "QuadraticInputs", "rk4_linear"]


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


def output_function(name: str, function: Callable) -> Callable:
    """Check that ``function(y)`` maps a float to one finite float; return it."""
    if not callable(function):
        raise ParameterError(f"{name}: expected a function of y, got {function!r}")
    try:
        values = [float(function(y)) for y in (0.0, 1.0)]
    except Exception as exc:
        raise ParameterError(f"{name}: {name}(y) must return one number: {type(exc).__name__}: {exc}") from None
    if not all(math.isfinite(v) for v in values):
        raise ParameterError(f"{name}: {name}(0) or {name}(1) is not finite: {values}")
    return function


@dataclass(frozen=True)
class Parabola:
    """A scalar input over one step: ``value(s) = start + s slope + curvature s (s - h)``."""

    start: float
    slope: float
    curvature: float
    h: float

    def at(self, s: float) -> float:
        return self.start + s * self.slope + self.curvature * s * (s - self.h)

    def max_rate(self) -> float:
        """Largest ``|d value / ds|`` on ``[0, h]`` (reached at an end)."""
        return abs(self.slope) + abs(self.curvature) * self.h


class QuadraticInputs:
    """Turns each block input's consecutive segments into :class:`Parabola` s (module docstring).

    Part of the block's state: :meth:`parabolas` does not change it, :meth:`commit` (called
    once the block's step has succeeded) does.
    """

    def __init__(self):
        self._last: dict[str, tuple[float, float, float, float]] = {}   # name -> (t, h, start, slope)

    def parabolas(self, t: float, h: float, segments) -> dict[str, Parabola]:
        """The inputs over ``[t, t + h]``; :class:`~observers.checks.SignalError` on NaN/inf."""
        for name, segment in segments.items():
            finite_signal(f"input {name}", np.concatenate([segment.start, segment.slope]))
        return {name: self._parabola(name, t, h, segment) for name, segment in segments.items()}

    def _parabola(self, name: str, t: float, h: float, segment: Segment) -> Parabola:
        start, slope = float(segment.start[0]), float(segment.slope[0])
        curvature = 0.0
        last = self._last.get(name)
        if last is not None:
            t_prev, h_prev, start_prev, slope_prev = last
            end_prev = start_prev + h_prev * slope_prev
            continues = (abs(t_prev + h_prev - t) <= 1e-9 * max(1.0, abs(t))
                         and abs(end_prev - start) <= 1e-12 * max(1.0, abs(start), abs(end_prev)))
            if continues:
                curvature = (slope - slope_prev) / (h + h_prev)
        return Parabola(start, slope, curvature, h)

    def commit(self, t: float, h: float, segments) -> None:
        for name, segment in segments.items():
            self._last[name] = (t, h, float(segment.start[0]), float(segment.slope[0]))


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
        b1 = th - 1.5 * th ** 2 + 2.0 / 3.0 * th ** 3
        b23 = th ** 2 - 2.0 / 3.0 * th ** 3
        b4 = -0.5 * th ** 2 + 2.0 / 3.0 * th ** 3
        inside.append(S + dt * (b1 * k1 + b23 * (k2 + k3) + b4 * k4))
    return S_end, inside
