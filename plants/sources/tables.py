"""Tables of break points and CSV columns, linear or previous-value interpolation."""

from __future__ import annotations

import csv
import io
import math
import os
import stat

import numpy as np

from obsfmu.observers.checks import ParameterError, as_vector

from .base import Source

__all__ = ["Table", "CsvColumn"]


#: Table.value in C (Source.c_value): p = N, linear, times (N), values (N)
_C_VALUE = """\
static double source_value(double t, const double *p)
{
    const size_t count = (size_t)p[0];
    const double *x = p + 2, *y = p + 2 + count;
    size_t low = 0, high = count;                                /* the first time after t: searchsorted right */
    while (low < high) {
        size_t middle = low + (high - low) / 2;
        if (x[middle] <= t) low = middle + 1; else high = middle;
    }
    if (p[1] == 0.0)                                             /* previous: values[max(i, 0)] */
        return y[low > 0 ? low - 1 : 0];
    if (count == 1) return y[0];                                 /* numpy.interp's rules from here */
    if (t != t) return t;
    if (low == 0) return y[0];                                   /* before the table */
    if (low == count) return y[count - 1];                       /* at or after its last time */
    size_t j = low - 1;
    if (x[j] == t) return y[j];
    double slope = (y[j + 1] - y[j]) / (x[j + 1] - x[j]), value = slope * (t - x[j]) + y[j];
    if (value != value) {                                        /* NaN one way: the other, then a flat piece */
        value = slope * (t - x[j + 1]) + y[j + 1];
        if (value != value && y[j] == y[j + 1]) value = y[j];
    }
    return value;
}"""


class Table(Source):
    """Piecewise-linear (``interpolation="linear"``) or previous-value (``"previous"``) table of
    ``(times_i, values_i)``, ``times`` strictly increasing; held at ``values_0`` before ``times_0``
    and at the last value after the last time.

    Linear: ``y = values_i + s_i (t - times_i)``, ``s_i = (values_{i+1} - values_i) / (times_{i+1} - times_i)``
    on ``[times_i, times_{i+1})``; ``derivative`` is ``s_i`` there and 0 outside the table.
    Previous: ``y = values_i`` on ``[times_i, times_{i+1})``, ``derivative`` 0.

    Parameters
    ----------
    times : array_like
        Break points (s), strictly increasing, at least one.
    values : array_like
        The values there, as many.
    interpolation : {"linear", "previous"}
        Between the break points.
    names : tuple of str
        Names of ``times`` and ``values`` in error messages (for :class:`CsvColumn`).
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

    def parameters(self) -> np.ndarray:
        """The count ``N``, 1 for linear (0 previous), the ``N`` times and the ``N`` values (:meth:`c_value`)."""
        return np.concatenate([[self.times.size, self.interpolation == "linear"], self.times, self.values])

    def c_value(self) -> str:
        """:meth:`value` in C: numpy's ``interp`` (its rules at and beyond the ends) or the previous value."""
        return _C_VALUE

    def derivative(self, t):
        i = self._segment(t)
        slopes = self._slopes if self.interpolation == "linear" else np.zeros_like(self._slopes)
        return np.where(i >= 0, slopes[np.maximum(i, 0)], 0.0)


def _columns(header: list[str]) -> str:
    """The header's names for a message, only when it looks like one (comma-separated short names): the first
    line of an arbitrary file is not quoted."""
    names = [name for name in header if name]
    if len(names) >= 2 and all(len(name) <= 40 and name.isprintable() for name in names):
        return "columns: " + ", ".join(names[:20]) + (", ..." if len(names) > 20 else "")
    return "its first line is not a header of comma-separated column names"


def _cell_text(cell: str) -> str:
    """A cell of the file for a message: escaped (repr) and at most 24 characters of it."""
    return repr(cell) if len(cell) <= 24 else repr(cell[:24]) + f"... ({len(cell)} characters)"


class CsvColumn(Table):
    """A column of a CSV file with a header row, against its ``time_column``, as a :class:`Table`.

    The file is read once, here; a missing file or column, a row without the column, a value that is
    not a finite number or times that do not increase raise :class:`ParameterError` naming the file,
    the column and the row (the file's line number, the header being line 1).  Blank lines are skipped.

    Parameters
    ----------
    path : str or path-like
        The CSV file (UTF-8, comma-separated, a header row of column names).
    column : str
        The column of values.
    time_column : str
        The column of times, strictly increasing.
    interpolation : {"linear", "previous"}
        As :class:`Table`.
    """

    not_state = ("path", "column")
    #: the largest file read (a column of a CSV file of 64 MiB: millions of rows)
    MAX_BYTES = 64 * 2 ** 20

    def __init__(self, path, column: str, time_column: str = "time", interpolation: str = "linear"):
        self.path, self.column = str(path), column
        times, values = self._read(time_column)
        super().__init__(times, values, interpolation, names=(f"{self.path}: column {time_column!r}",
                                                              f"{self.path}: column {column!r}"))

    def _read(self, time_column: str) -> tuple[list[float], list[float]]:
        rows = list(csv.reader(io.StringIO(self._text(), newline="")))
        if not rows:
            raise ParameterError(f"path: {self.path} is empty (expected a header row)")
        header = [name.strip() for name in rows[0]]
        for name, what in ((time_column, "time_column"), (self.column, "column")):
            if name not in header:
                raise ParameterError(f"{what}: {name!r} is not a column of {self.path} ({_columns(header)})")
        picked = [(header.index(time_column), time_column), (header.index(self.column), self.column)]
        times, values, previous = [], [], None
        for line, row in enumerate(rows[1:], start=2):
            if not any(cell.strip() for cell in row):
                continue
            time, value = (self._cell(row, index, name, line) for index, name in picked)
            if previous is not None and time <= previous[1]:
                raise ParameterError(f"{self.path}: row {line}: time {time:g} is not after "
                                     f"{previous[1]:g} of row {previous[0]}")
            previous = (line, time)
            times.append(time)
            values.append(value)
        if not times:
            raise ParameterError(f"path: {self.path} has a header but no data rows")
        return times, values

    def _text(self) -> str:
        """The file's text: a regular file (not a device, FIFO or folder) of at most :attr:`MAX_BYTES`, read with
        that bound (a file growing meanwhile is cut there and refused).  Messages quote nothing of it."""
        try:
            status = os.stat(self.path)
            if not stat.S_ISREG(status.st_mode):
                raise ParameterError(f"path: {self.path} is not a regular file (a device, FIFO or folder cannot be "
                                     f"read as a CSV file)")
            if status.st_size > self.MAX_BYTES:
                raise ParameterError(f"path: {self.path} has {status.st_size} bytes, more than the limit of "
                                     f"{self.MAX_BYTES // 2 ** 20} MiB")
            with open(self.path, "rb") as file:
                data = file.read(self.MAX_BYTES + 1)
        except OSError as exc:
            raise ParameterError(f"path: cannot read {self.path}: {exc.strerror or type(exc).__name__}") from None
        if len(data) > self.MAX_BYTES:
            raise ParameterError(f"path: {self.path} grew beyond the limit of {self.MAX_BYTES // 2 ** 20} MiB while read")
        try:
            return data.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            raise ParameterError(f"path: {self.path} is not UTF-8 text (byte {exc.start + 1})") from None

    def _cell(self, row: list[str], index: int, name: str, line: int) -> float:
        where = f"{self.path}: row {line}, column {name!r}"
        if index >= len(row):
            raise ParameterError(f"{where}: missing (the row has {len(row)} cells)")
        try:
            number = float(row[index])
        except ValueError:
            raise ParameterError(f"{where}: expected a number, got {_cell_text(row[index])}") from None
        if not math.isfinite(number):
            raise ParameterError(f"{where}: {_cell_text(row[index])} is not finite")
        return number
