"""Deterministic signal sources: constant, step, ramp, sine, multi-sine, chirp, square, PRBS, table, CSV.

Each source is a stateless :class:`~observers.block.Block` without inputs and with one output
``y`` (size 1): ``y(t) = value(t)``.  Each also offers ``derivative(t)``, the exact time
derivative where the signal is smooth -- a master sends it as the input derivative, so linear
coupling of a smooth source stays exact.  At a discontinuity (step time, square edge, PRBS bit
boundary, table break point) ``derivative`` is the one-sided derivative from the right, and
``value`` is right-continuous: the value at a switching time is the value after it.

Frequencies are in hertz everywhere (the parameters say so: ``frequency_hz``, ``f0_hz``), phases
in radians.  ``value`` and ``derivative`` accept a float or an array of times.

Interval boundaries (square edges, PRBS bits, noise samples) are found with
:func:`interval_index`, which counts a time within ``1e-9`` of an interval of a boundary as on
it, so ``t = k * dt`` computed in floating point lands on interval ``k``.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Mapping

import numpy as np

from observers.block import Block, Segment
from observers.checks import ParameterError, as_vector, require_positive

__all__ = ["interval_index", "Source", "PiecewiseConstant", "Constant", "Step", "Ramp", "MultiSine", "Sine", "Chirp",
           "Square", "PRBS", "PRIMITIVE_TAPS", "Table", "CsvColumn"]

#: fraction of an interval within which a time counts as on the next boundary
BOUNDARY_TOLERANCE = 1e-9


def interval_index(t, dt: float):
    """Index ``k`` of the interval ``[k dt, (k + 1) dt)`` holding ``t``; negative times give 0."""
    k = np.floor(np.asarray(t, dtype=float) / dt + BOUNDARY_TOLERANCE).astype(np.int64)
    return np.maximum(k, 0)


def _number(name: str, value) -> float:
    return float(as_vector(name, value, 1)[0])


class Source(Block):
    """Base of every source: no inputs, ``y = [value(t)]``, nothing to integrate.

    A subclass sets its parameters in ``__init__`` (after ``super().__init__()``), lists them in
    ``not_state`` and implements ``value(t)`` and ``derivative(t)``.
    """

    stateless = True

    def __init__(self):
        self.input_sizes = {}
        self.output_sizes = {"y": 1}

    def value(self, t):
        raise NotImplementedError

    def derivative(self, t):
        raise NotImplementedError

    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {"y": np.array([float(self.value(t))])}

    def advance(self, t: float, h: float, inputs: Mapping[str, Segment]) -> None:
        """Nothing to integrate: the output is a function of time."""


class PiecewiseConstant(Source):
    """A source that only jumps: ``derivative(t) = 0`` (from the right at a jump too)."""

    def derivative(self, t):
        return 0.0 * np.asarray(t, dtype=float)


class Constant(PiecewiseConstant):
    """``y(t) = value``."""

    not_state = ("level",)

    def __init__(self, value: float = 0.0):
        super().__init__()
        self.level = _number("value", value)

    def value(self, t):
        return self.level + 0.0 * np.asarray(t, dtype=float)


class Step(PiecewiseConstant):
    """``y(t) = offset + height * [t >= time]``."""

    not_state = ("time", "height", "offset")

    def __init__(self, time: float = 0.0, height: float = 1.0, offset: float = 0.0):
        super().__init__()
        self.time, self.height, self.offset = _number("time", time), _number("height", height), _number("offset", offset)

    def value(self, t):
        return self.offset + self.height * (np.asarray(t, dtype=float) >= self.time)


class Ramp(Source):
    """``y(t) = offset + slope * clip(t - start_time, 0, end_time - start_time)``.

    Without ``end_time`` the ramp never saturates; with it the output holds from ``end_time`` on.
    """

    not_state = ("start_time", "slope", "offset", "end_time")

    def __init__(self, start_time: float = 0.0, slope: float = 1.0, offset: float = 0.0, end_time: float | None = None):
        super().__init__()
        self.start_time, self.slope = _number("start_time", start_time), _number("slope", slope)
        self.offset = _number("offset", offset)
        self.end_time = math.inf if end_time is None else _number("end_time", end_time)
        if self.end_time <= self.start_time:
            raise ParameterError(f"end_time: must be after start_time = {self.start_time:g}, got {self.end_time:g}")

    def value(self, t):
        elapsed = np.clip(np.asarray(t, dtype=float) - self.start_time, 0.0, self.end_time - self.start_time)
        return self.offset + self.slope * elapsed

    def derivative(self, t):
        t = np.asarray(t, dtype=float)
        return self.slope * ((t >= self.start_time) & (t < self.end_time))


class MultiSine(Source):
    """``y(t) = offset + sum_i amplitudes_i sin(2 pi frequencies_hz_i t + phases_i)``."""

    not_state = ("amplitudes", "omega", "phases", "offset")

    def __init__(self, amplitudes, frequencies_hz, phases=None, offset: float = 0.0, names=("amplitudes", "frequencies_hz", "phases")):
        super().__init__()
        self.amplitudes = as_vector(names[0], amplitudes)
        count = self.amplitudes.size
        frequencies = as_vector(names[1], frequencies_hz, count)
        if np.any(frequencies < 0):
            raise ParameterError(f"{names[1]}: must be >= 0, got {frequencies.tolist()}")
        self.omega = 2.0 * np.pi * frequencies
        self.phases = np.zeros(count) if phases is None else as_vector(names[2], phases, count)
        self.offset = _number("offset", offset)

    def _angles(self, t):
        return np.multiply.outer(np.asarray(t, dtype=float), self.omega) + self.phases

    def value(self, t):
        return self.offset + np.sin(self._angles(t)) @ self.amplitudes

    def derivative(self, t):
        return np.cos(self._angles(t)) @ (self.amplitudes * self.omega)


class Sine(MultiSine):
    """``y(t) = offset + amplitude sin(2 pi frequency_hz t + phase)``."""

    def __init__(self, amplitude: float = 1.0, frequency_hz: float = 1.0, phase: float = 0.0, offset: float = 0.0):
        super().__init__([_number("amplitude", amplitude)], [_number("frequency_hz", frequency_hz)],
                         [_number("phase", phase)], offset, names=("amplitude", "frequency_hz", "phase"))


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
    """

    not_state = ("amplitude", "f0", "f1", "t0", "t1", "sweep", "after", "phase", "offset")

    def __init__(self, amplitude: float = 1.0, f0_hz: float = 0.1, f1_hz: float = 10.0, t0: float = 0.0, t1: float = 10.0,
                 sweep: str = "linear", after: str = "hold", phase: float = 0.0, offset: float = 0.0):
        super().__init__()
        self.amplitude, self.phase, self.offset = _number("amplitude", amplitude), _number("phase", phase), _number("offset", offset)
        if sweep not in ("linear", "exponential"):
            raise ParameterError(f"sweep: expected 'linear' or 'exponential', got {sweep!r}")
        if after not in ("hold", "stop"):
            raise ParameterError(f"after: expected 'hold' or 'stop', got {after!r}")
        self.sweep, self.after = sweep, after
        allow_zero = sweep == "linear"
        self.f0, self.f1 = require_positive("f0_hz", f0_hz, allow_zero), require_positive("f1_hz", f1_hz, allow_zero)
        self.t0, self.t1 = _number("t0", t0), _number("t1", t1)
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

    def derivative(self, t):
        phi, frequency, t = self._phase_and_frequency(t)
        return self.amplitude * 2 * np.pi * frequency * np.cos(phi) * self._active(t)


class Square(PiecewiseConstant):
    """``y(t) = offset + amplitude`` for the first ``duty`` fraction of each period from ``t = 0``,
    ``offset - amplitude`` for the rest (zero mean about ``offset`` at ``duty = 0.5``)."""

    not_state = ("amplitude", "period", "duty", "offset")

    def __init__(self, amplitude: float = 1.0, period: float = 1.0, duty: float = 0.5, offset: float = 0.0):
        super().__init__()
        self.amplitude, self.offset = _number("amplitude", amplitude), _number("offset", offset)
        self.period = require_positive("period", period)
        self.duty = _number("duty", duty)
        if not 0.0 < self.duty < 1.0:
            raise ParameterError(f"duty: must be in (0, 1), got {self.duty:g}")

    def value(self, t):
        cycles = np.asarray(t, dtype=float) / self.period
        fraction = cycles - np.floor(cycles + BOUNDARY_TOLERANCE)
        return self.offset + self.amplitude * np.where(fraction < self.duty - BOUNDARY_TOLERANCE, 1.0, -1.0)


#: feedback taps of a maximal-length Fibonacci LFSR for each register length (Xilinx XAPP052):
#: ``a[k + n] = XOR of a[k + n - tap]`` over the taps, characteristic polynomial
#: ``x^n + sum_tap x^(n - tap)``, primitive over GF(2) (checked by the tests)
PRIMITIVE_TAPS = {
    2: (2, 1), 3: (3, 2), 4: (4, 3), 5: (5, 3), 6: (6, 5), 7: (7, 6), 8: (8, 6, 5, 4), 9: (9, 5), 10: (10, 7),
    11: (11, 9), 12: (12, 6, 4, 1), 13: (13, 4, 3, 1), 14: (14, 5, 3, 1), 15: (15, 14), 16: (16, 15, 13, 4),
    17: (17, 14), 18: (18, 11), 19: (19, 6, 2, 1), 20: (20, 17), 21: (21, 19), 22: (22, 21), 23: (23, 18),
    24: (24, 23, 22, 17), 25: (25, 22), 26: (26, 6, 2, 1), 27: (27, 5, 2, 1), 28: (28, 25), 29: (29, 27),
    30: (30, 6, 4, 1), 31: (31, 28), 32: (32, 22, 2, 1),
}


class PRBS(PiecewiseConstant):
    """Pseudo-random binary sequence of a maximal-length LFSR: ``y = offset + amplitude (2 a_k - 1)``
    on bit interval ``k`` (``[k bit_period, (k + 1) bit_period)``, negative times in bit 0).

    ``a_0 .. a_{n-1}`` are the bits of ``seed`` (``a_j = (seed >> j) & 1``, ``1 <= seed < 2^n``), and
    ``a_{k+n} = XOR_tap a_{k+n-tap}`` with the taps of :data:`PRIMITIVE_TAPS` for ``n = register_length``:
    the textbook m-sequence of period ``2^n - 1`` with ``2^(n-1)`` ones.  ``a_k`` is computed directly
    from ``(seed, k)`` as ``x^k mod p(x)`` applied to the initial bits (``O(n log k)``), so it does not
    depend on the order or frequency of evaluation.
    """

    not_state = ("amplitude", "bit_period", "seed", "register_length", "offset", "_polynomial")

    def __init__(self, amplitude: float = 1.0, bit_period: float = 1.0, seed: int = 1, register_length: int = 7,
                 offset: float = 0.0):
        super().__init__()
        self.amplitude, self.offset = _number("amplitude", amplitude), _number("offset", offset)
        self.bit_period = require_positive("bit_period", bit_period)
        if register_length not in PRIMITIVE_TAPS or int(register_length) != register_length:
            raise ParameterError(f"register_length: expected an integer from 2 to 32, got {register_length!r}")
        n = self.register_length = int(register_length)
        if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or not 1 <= seed < 2 ** n:
            raise ParameterError(f"seed: expected an integer from 1 to 2^{n} - 1 = {2 ** n - 1}, got {seed!r}")
        self.seed = int(seed)
        # bit j of the polynomial = coefficient of x^j, the leading x^n included
        self._polynomial = (1 << n) | sum(1 << (n - tap) for tap in PRIMITIVE_TAPS[n])

    def _times_x(self, r: int) -> int:
        r <<= 1
        return r ^ self._polynomial if r >> self.register_length & 1 else r

    def _multiply(self, a: int, b: int) -> int:
        """``a(x) b(x) mod p(x)`` over GF(2)."""
        product = 0
        while b:
            if b & 1:
                product ^= a
            b >>= 1
            a = self._times_x(a)
        return product

    def bit(self, k: int) -> int:
        """``a_k`` (0 or 1): ``x^k mod p = sum_j r_j x^j`` gives ``a_k = XOR_j r_j a_j``."""
        result, power = 1, 2           # x^0, x^1
        while k:
            if k & 1:
                result = self._multiply(result, power)
            power = self._multiply(power, power)
            k >>= 1
        return bin(result & self.seed).count("1") & 1

    def value(self, t):
        k = interval_index(t, self.bit_period)
        bits = np.vectorize(self.bit, otypes=[float])(k) if k.ndim else float(self.bit(int(k)))
        return self.offset + self.amplitude * (2.0 * np.asarray(bits) - 1.0)


class Table(Source):
    """Piecewise-linear (``interpolation="linear"``) or previous-value (``"previous"``) table of
    ``(times_i, values_i)``, ``times`` strictly increasing; held at ``values_0`` before ``times_0``
    and at the last value after the last time.

    Linear: ``y = values_i + s_i (t - times_i)``, ``s_i = (values_{i+1} - values_i) / (times_{i+1} - times_i)``
    on ``[times_i, times_{i+1})``; ``derivative`` is ``s_i`` there and 0 outside the table.
    """

    not_state = ("times", "values", "interpolation", "_slopes")

    def __init__(self, times, values, interpolation: str = "linear", names=("times", "values")):
        super().__init__()
        self.times = as_vector(names[0], times)
        if self.times.size == 0:
            raise ParameterError(f"{names[0]}: expected at least one entry")
        self.values = as_vector(names[1], values, self.times.size)
        steps = np.diff(self.times)
        if np.any(steps <= 0):
            i = int(np.argmax(steps <= 0)) + 1
            raise ParameterError(f"{names[0]}: must be strictly increasing, entry {i + 1} ({self.times[i]:g}) "
                                 f"is not after entry {i} ({self.times[i - 1]:g})")
        if interpolation not in ("linear", "previous"):
            raise ParameterError(f"interpolation: expected 'linear' or 'previous', got {interpolation!r}")
        self.interpolation = interpolation
        self._slopes = np.append(np.diff(self.values) / steps, 0.0)

    def _segment(self, t):
        return np.searchsorted(self.times, np.asarray(t, dtype=float), side="right") - 1

    def value(self, t):
        if self.interpolation == "linear":
            return np.interp(np.asarray(t, dtype=float), self.times, self.values)
        return self.values[np.maximum(self._segment(t), 0)]

    def derivative(self, t):
        i = self._segment(t)
        slopes = self._slopes if self.interpolation == "linear" else np.zeros_like(self._slopes)
        return np.where(i >= 0, slopes[np.maximum(i, 0)], 0.0)


class CsvColumn(Table):
    """A column of a CSV file with a header row, against its ``time_column``, as a :class:`Table`.

    The file is read once, here; a missing file or column, a row without the column, a value that is
    not a finite number or times that do not increase raise :class:`ParameterError` naming the file,
    the column and the row (the file's line number, the header being line 1).
    """

    not_state = ("path", "column")

    def __init__(self, path, column: str, time_column: str = "time", interpolation: str = "linear"):
        self.path, self.column = str(path), column
        times, values = self._read(time_column)
        super().__init__(times, values, interpolation, names=(f"{self.path}: column {time_column!r}",
                                                              f"{self.path}: column {column!r}"))

    def _read(self, time_column: str) -> tuple[list[float], list[float]]:
        try:
            with Path(self.path).open(newline="", encoding="utf-8-sig") as file:
                rows = list(csv.reader(file))
        except (OSError, UnicodeDecodeError, csv.Error) as exc:
            raise ParameterError(f"path: cannot read {self.path!r}: {exc}") from exc
        if not rows:
            raise ParameterError(f"path: {self.path} is empty (expected a header row)")
        header = [name.strip() for name in rows[0]]
        for name, what in ((time_column, "time_column"), (self.column, "column")):
            if name not in header:
                raise ParameterError(f"{what}: {name!r} is not a column of {self.path} (columns: {', '.join(header)})")
        picked = [(header.index(time_column), time_column), (header.index(self.column), self.column)]
        times, values, previous = [], [], None
        for line, row in enumerate(rows[1:], start=2):
            if not any(cell.strip() for cell in row):
                continue
            time, value = (self._cell(row, index, name, line) for index, name in picked)
            if previous is not None and time <= previous[1]:
                raise ParameterError(f"{self.path}: row {line}: time {time:g} is not after {previous[1]:g} of row {previous[0]}")
            previous = (line, time)
            times.append(time)
            values.append(value)
        if not times:
            raise ParameterError(f"path: {self.path} has a header but no data rows")
        return times, values

    def _cell(self, row: list[str], index: int, name: str, line: int) -> float:
        where = f"{self.path}: row {line}, column {name!r}"
        if index >= len(row):
            raise ParameterError(f"{where}: missing (the row has {len(row)} cells)")
        try:
            number = float(row[index])
        except ValueError:
            raise ParameterError(f"{where}: expected a number, got {row[index]!r}") from None
        if not math.isfinite(number):
            raise ParameterError(f"{where}: {row[index]!r} is not finite")
        return number
