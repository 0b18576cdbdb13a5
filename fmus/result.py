"""Co-simulation results: a time vector and one column per recorded variable, with what the run was."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["Result", "RunInfo"]


@dataclass
class RunInfo:
    """How a scenario run was made: what a summary or a figure needs beyond the numbers.

    ``parameters`` are the start values every parameter of every instance had in the run
    (``instance.variable``: the FMU's declared start, the scenario's start values, then
    ``--set``); ``defaults`` the same without ``--set``.  ``units`` maps recorded columns to
    the units the FMUs declare (absent: none declared).
    """

    scenario: str = ""
    time_unit: str = "s"
    start_time: float = 0.0
    stop_time: float = 0.0
    step: float = 0.0
    order: str = ""
    coupling: str = ""
    units: dict[str, str] = field(default_factory=dict)
    parameters: dict[str, float] = field(default_factory=dict)
    defaults: dict[str, float] = field(default_factory=dict)

    @property
    def changed(self) -> dict[str, float]:
        """The parameters whose value in this run differs from the scenario's default."""
        return {name: value for name, value in self.parameters.items() if self.defaults.get(name) != value}


@dataclass
class Result:
    """``values[k, j]`` is column ``columns[j]`` (``instance.variable``) at ``time[k]``."""

    time: np.ndarray
    columns: list[str]
    values: np.ndarray
    interrupted: bool = False  #: the run was stopped before its stop time
    info: RunInfo | None = None  #: how the run was made (None: unknown, e.g. read from a CSV)

    def __getitem__(self, column: str) -> np.ndarray:
        try:
            return self.values[:, self.columns.index(column)]
        except ValueError:
            raise KeyError(f"{column!r} not recorded; columns: {self.columns}") from None

    def vector(self, prefix: str) -> np.ndarray:
        """All columns of an array port, e.g. ``vector("plant.x")`` -> shape ``(len(time), n)``."""
        names = self._names(prefix)
        return np.column_stack([self[c] for c in names])

    def _names(self, prefix: str) -> list[str]:
        names = [c for c in self.columns if c == prefix or c.startswith(prefix + "[")]
        if not names:
            raise KeyError(f"{prefix!r} not recorded; columns: {self.columns}")
        return names

    def unit(self, column: str) -> str:
        """Declared unit of a column or of a whole port (its first element); ``""`` if none is declared."""
        if self.info is None:
            return ""
        return self.info.units.get(column) or self.info.units.get(self._names(column)[0], "")

    @property
    def time_unit(self) -> str:
        return self.info.time_unit if self.info else "s"

    def index_at(self, t: float) -> int:
        """Index of the communication point nearest to ``t``."""
        return int(np.argmin(np.abs(self.time - t)))

    def at(self, times, prefix: str) -> np.ndarray:
        """The columns of ``prefix`` (as :meth:`vector`) at ``times`` within the run, through a cubic spline
        of the communication points.  Fourth order: a run on another grid than a reference (the adaptive
        master's) is compared with it at the reference's points without the reading's own error
        (linear interpolation, second order, would measure itself rather than the run)."""
        times = np.asarray(times, dtype=float)
        if times.size and (times.min() < self.time[0] - 1e-9 or times.max() > self.time[-1] + 1e-9):
            raise ValueError(f"times: {times.min():g} to {times.max():g} leave the run "
                             f"({self.time[0]:g} to {self.time[-1]:g})")
        from scipy.interpolate import CubicSpline
        return CubicSpline(self.time, self.vector(prefix))(times)

    def sampled(self, interval: float) -> "Result":
        """The rows nearest to ``t0, t0 + interval, ...`` and the last one (for smaller files)."""
        targets = np.append(np.arange(self.time[0], self.time[-1], interval), self.time[-1])
        right = np.clip(np.searchsorted(self.time, targets), 1, len(self.time) - 1)
        nearer_left = targets - self.time[right - 1] <= self.time[right] - targets
        rows = np.unique(np.where(nearer_left, right - 1, right))
        return Result(self.time[rows], list(self.columns), self.values[rows], self.interrupted, self.info)

    def to_csv(self, path: Path | str) -> None:
        """Write the whole result at once (``obsfmu run`` streams instead: :mod:`fmus.output`)."""
        header = ",".join(["time"] + self.columns)
        data = np.column_stack([self.time, self.values])
        np.savetxt(path, data, delimiter=",", header=header, comments="", fmt="%.17g")

    @classmethod
    def from_csv(cls, path: Path | str) -> "Result":
        with open(path) as handle:
            columns = handle.readline().strip().split(",")
        data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
        return cls(data[:, 0], columns[1:], data[:, 1:])
