"""Analytic waveforms: constant, step, ramp, sine, multi-sine, chirp, square (formulas in each class)."""

from __future__ import annotations

import math

import numpy as np

from obsfmu.observers.checks import ParameterError, as_vector, require_positive

from .base import BOUNDARY_TOLERANCE, PiecewiseConstant, Source, scalar_parameter

__all__ = ["Constant", "Step", "Ramp", "MultiSine", "Sine", "Chirp", "Square"]


class Constant(PiecewiseConstant):
    """``y(t) = value``.

    Parameters
    ----------
    value : float
        The level.
    """

    not_state = ("level",)

    def __init__(self, value: float = 0.0):
        super().__init__()
        self.level = scalar_parameter("value", value)

    def value(self, t):
        return self.level + 0.0 * np.asarray(t, dtype=float)

    def expression(self) -> str:
        return "p[1] + 0 * t"

    def parameters(self) -> np.ndarray:
        return np.array([self.level])


class Step(PiecewiseConstant):
    """``y(t) = offset + height * [t >= time]``.

    Parameters
    ----------
    time : float
        Switching time (s); the value at ``time`` is the one after the step.
    height, offset : float
        Step height and the level before it.
    """

    not_state = ("time", "height", "offset")

    def __init__(self, time: float = 0.0, height: float = 1.0, offset: float = 0.0):
        super().__init__()
        self.time, self.height = scalar_parameter("time", time), scalar_parameter("height", height)
        self.offset = scalar_parameter("offset", offset)

    def value(self, t):
        return self.offset + self.height * (np.asarray(t, dtype=float) >= self.time)

    def expression(self) -> str:
        return "p[1] + p[2] * (t >= p[3])"

    def parameters(self) -> np.ndarray:
        return np.array([self.offset, self.height, self.time])


class Ramp(Source):
    """``y(t) = offset + slope * clip(t - start_time, 0, end_time - start_time)``.

    Parameters
    ----------
    start_time : float
        Time (s) the ramp starts; ``offset`` before it.
    slope : float
        Rate (units/s).
    offset : float
        Level before ``start_time``.
    end_time : float, optional
        Saturation: the output holds from ``end_time`` on (after ``start_time``); without it, never.
    """

    not_state = ("start_time", "slope", "offset", "end_time")

    def __init__(self, start_time: float = 0.0, slope: float = 1.0, offset: float = 0.0, end_time: float | None = None):
        super().__init__()
        self.start_time, self.slope = scalar_parameter("start_time", start_time), scalar_parameter("slope", slope)
        self.offset = scalar_parameter("offset", offset)
        self.end_time = math.inf if end_time is None else scalar_parameter("end_time", end_time)
        if self.end_time <= self.start_time:
            raise ParameterError(f"end_time: must be after start_time = {self.start_time:g}, got {self.end_time:g}")

    def value(self, t):
        elapsed = np.clip(np.asarray(t, dtype=float) - self.start_time, 0.0, self.end_time - self.start_time)
        return self.offset + self.slope * elapsed

    def expression(self) -> str:
        return "p[1] + p[2] * clip(t - p[3], 0, p[4] - p[3])"

    def parameters(self) -> np.ndarray:
        return np.array([self.offset, self.slope, self.start_time, self.end_time])

    def derivative(self, t):
        t = np.asarray(t, dtype=float)
        return self.slope * ((t >= self.start_time) & (t < self.end_time))


class MultiSine(Source):
    """``y(t) = offset + sum_i amplitudes_i sin(2 pi frequencies_hz_i t + phases_i)``.

    Parameters
    ----------
    amplitudes : array_like
        One amplitude per sine.
    frequencies_hz : array_like
        Their frequencies (Hz, >= 0), as many.
    phases : array_like, optional
        Their phases (rad) at ``t = 0``; zero by default.
    offset : float
        Constant added.
    names : tuple of str
        Names of the first three parameters in error messages (for :class:`Sine`).
    """

    not_state = ("amplitudes", "omega", "phases", "offset")

    def __init__(self, amplitudes, frequencies_hz, phases=None, offset: float = 0.0,
                 names=("amplitudes", "frequencies_hz", "phases")):
        super().__init__()
        self.amplitudes = as_vector(names[0], amplitudes)
        count = self.amplitudes.size
        frequencies = as_vector(names[1], frequencies_hz, count)
        if np.any(frequencies < 0):
            raise ParameterError(f"{names[1]}: must be >= 0, got {frequencies.tolist()}")
        self.omega = 2.0 * np.pi * frequencies
        self.phases = np.zeros(count) if phases is None else as_vector(names[2], phases, count)
        self.offset = scalar_parameter("offset", offset)

    def _angles(self, t):
        return np.multiply.outer(np.asarray(t, dtype=float), self.omega) + self.phases

    def value(self, t):
        return self.offset + np.sin(self._angles(t)) @ self.amplitudes

    def expression(self) -> str:
        k = self.amplitudes.size
        terms = " + ".join(f"sin(t * p[{2 + k + i}] + p[{2 + 2 * k + i}]) * p[{2 + i}]" for i in range(k))
        return f"p[1] + ({terms})"

    def parameters(self) -> np.ndarray:
        return np.concatenate([[self.offset], self.amplitudes, self.omega, self.phases])

    def derivative(self, t):
        return np.cos(self._angles(t)) @ (self.amplitudes * self.omega)


class Sine(MultiSine):
    """``y(t) = offset + amplitude sin(2 pi frequency_hz t + phase)``: a :class:`MultiSine` of one term.

    Parameters
    ----------
    amplitude, frequency_hz, phase, offset : float
        As the first term of :class:`MultiSine` (frequency in Hz, phase in rad).
    """

    def __init__(self, amplitude: float = 1.0, frequency_hz: float = 1.0, phase: float = 0.0, offset: float = 0.0):
        super().__init__([scalar_parameter("amplitude", amplitude)], [scalar_parameter("frequency_hz", frequency_hz)],
                         [scalar_parameter("phase", phase)], offset, names=("amplitude", "frequency_hz", "phase"))


class Chirp(Source):
    """A sweep from ``f0_hz`` to ``f1_hz`` over ``[t0, t1]``: ``y = offset + amplitude sin(phi(t))``.

    With ``tau = t - t0``, ``T = t1 - t0``, the phase for ``t0 <= t <= t1`` is

    * ``sweep="linear"``: ``phi = phase + 2 pi (f0 tau + (f1 - f0) tau^2 / (2 T))``
      (instantaneous frequency ``f0 + (f1 - f0) tau / T``);
    * ``sweep="exponential"``: ``phi = phase + 2 pi f0 T (r^(tau/T) - 1) / ln r``, ``r = f1 / f0``
      (instantaneous frequency ``f0 r^(tau/T)``; both frequencies > 0).

    Before ``t0`` the output is ``offset`` (the sweep has not begun).  After ``t1``:
    ``after="hold"`` goes on at ``f1`` with a continuous phase, ``phi = phi(t1) + 2 pi f1 (t - t1)``;
    ``after="stop"`` gives ``offset``.

    Parameters
    ----------
    amplitude, offset : float
        ``y = offset + amplitude sin(phi)``.
    f0_hz, f1_hz : float
        Start and end frequencies (Hz; >= 0 linear, > 0 exponential).
    t0, t1 : float
        The sweep interval (s), ``t1 > t0``.
    sweep : {"linear", "exponential"}
        How the frequency goes from ``f0_hz`` to ``f1_hz``.
    after : {"hold", "stop"}
        What follows ``t1``: the sine at ``f1_hz``, or ``offset``.
    phase : float
        Phase (rad) at ``t0``.
    """

    not_state = ("amplitude", "f0", "f1", "t0", "t1", "sweep", "after", "phase", "offset")

    def __init__(self, amplitude: float = 1.0, f0_hz: float = 0.1, f1_hz: float = 10.0, t0: float = 0.0,
                 t1: float = 10.0, sweep: str = "linear", after: str = "hold", phase: float = 0.0, offset: float = 0.0):
        super().__init__()
        self.amplitude, self.phase = scalar_parameter("amplitude", amplitude), scalar_parameter("phase", phase)
        self.offset = scalar_parameter("offset", offset)
        if sweep not in ("linear", "exponential"):
            raise ParameterError(f"sweep: expected 'linear' or 'exponential', got {sweep!r}")
        if after not in ("hold", "stop"):
            raise ParameterError(f"after: expected 'hold' or 'stop', got {after!r}")
        self.sweep, self.after = sweep, after
        allow_zero = sweep == "linear"
        self.f0, self.f1 = require_positive("f0_hz", f0_hz, allow_zero), require_positive("f1_hz", f1_hz, allow_zero)
        self.t0, self.t1 = scalar_parameter("t0", t0), scalar_parameter("t1", t1)
        if self.t1 <= self.t0:
            raise ParameterError(f"t1: must be after t0 = {self.t0:g}, got {self.t1:g}")

    def _sweep(self, tau):
        """Phase increment and instantaneous frequency (Hz) at ``tau = t - t0`` in ``[0, T]``."""
        T, f0, f1 = self.t1 - self.t0, self.f0, self.f1
        if self.sweep == "linear" or f0 == f1:
            return 2 * np.pi * (f0 * tau + (f1 - f0) * tau ** 2 / (2 * T)), f0 + (f1 - f0) * tau / T
        ratio = f1 / f0
        growth = ratio ** (tau / T)
        return 2 * np.pi * f0 * T * (growth - 1) / math.log(ratio), f0 * growth

    def _phase_and_frequency(self, t):
        t = np.asarray(t, dtype=float)
        T = self.t1 - self.t0
        inside, frequency = self._sweep(np.clip(t - self.t0, 0.0, T))
        beyond = np.maximum(t - self.t1, 0.0)
        return self.phase + inside + 2 * np.pi * self.f1 * beyond, frequency, t

    def _active(self, t):
        return (t >= self.t0) & ((t < self.t1) | (self.after == "hold"))

    def value(self, t):
        phi, _, t = self._phase_and_frequency(t)
        return self.offset + self.amplitude * np.sin(phi) * self._active(t)

    def expression(self) -> str:
        """:meth:`value` in the expression language, the same operations in the same order (the compiled kernel's
        output), reading :meth:`parameters` as ``p``."""
        tau = "clip(t - p[6], 0, p[8])"
        if self.sweep == "linear" or self.f0 == self.f1:
            inside = f"p[10] * (p[4] * {tau} + (p[5] - p[4]) * {tau} ^ 2 / (2 * p[8]))"
        else:
            inside = f"p[10] * p[4] * p[8] * (p[11] ^ ({tau} / p[8]) - 1) / p[12]"
        phi = f"p[3] + {inside} + p[10] * p[5] * max(t - p[7], 0)"
        return f"p[1] + p[2] * sin({phi}) * ((t >= p[6]) and ((t < p[7]) or p[9]))"

    def parameters(self) -> np.ndarray:
        """offset, amplitude, phase, f0, f1, t0, t1, T = t1 - t0, after hold (1) or stop (0), 2 pi, f1 / f0 and its
        logarithm (1 and 0 for a linear sweep)."""
        exponential = self.sweep == "exponential" and self.f0 != self.f1
        ratio = self.f1 / self.f0 if exponential else 1.0
        return np.array([self.offset, self.amplitude, self.phase, self.f0, self.f1, self.t0, self.t1, self.t1 - self.t0,
                         float(self.after == "hold"), 2 * np.pi, ratio, math.log(ratio)])

    def derivative(self, t):
        phi, frequency, t = self._phase_and_frequency(t)
        return self.amplitude * 2 * np.pi * frequency * np.cos(phi) * self._active(t)


class Square(PiecewiseConstant):
    """``y(t) = offset + amplitude`` for the first ``duty`` fraction of each period from ``t = 0``,
    ``offset - amplitude`` for the rest (zero mean about ``offset`` at ``duty = 0.5``).

    Parameters
    ----------
    amplitude, offset : float
        Levels ``offset +- amplitude``.
    period : float
        Period (s), > 0.
    duty : float
        Fraction of the period at the high level, in (0, 1).
    """

    not_state = ("amplitude", "period", "duty", "offset")

    def __init__(self, amplitude: float = 1.0, period: float = 1.0, duty: float = 0.5, offset: float = 0.0):
        super().__init__()
        self.amplitude, self.offset = scalar_parameter("amplitude", amplitude), scalar_parameter("offset", offset)
        self.period = require_positive("period", period)
        self.duty = scalar_parameter("duty", duty)
        if not 0.0 < self.duty < 1.0:
            raise ParameterError(f"duty: must be in (0, 1), got {self.duty:g}")

    def value(self, t):
        cycles = np.asarray(t, dtype=float) / self.period
        fraction = cycles - np.floor(cycles + BOUNDARY_TOLERANCE)
        return self.offset + self.amplitude * np.where(fraction < self.duty - BOUNDARY_TOLERANCE, 1.0, -1.0)

    def expression(self) -> str:
        """:meth:`value` in the expression language, the same operations (the compiled kernel's output)."""
        return "p[1] + p[2] * where(t / p[3] - floor(t / p[3] + p[5]) < p[4] - p[5], 1, -1)"

    def parameters(self) -> np.ndarray:
        """offset, amplitude, period, duty, the boundary tolerance."""
        return np.array([self.offset, self.amplitude, self.period, self.duty, BOUNDARY_TOLERANCE])
