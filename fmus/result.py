"""Co-simulation results: a time vector and one column per recorded variable."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["Result"]


@dataclass
class Result:
    """``values[k, j]`` is column ``columns[j]`` (``instance.variable``) at ``time[k]``."""

    time: np.ndarray
    columns: list[str]
    values: np.ndarray
    interrupted: bool = False  #: the run was stopped before its stop time

    def __getitem__(self, column: str) -> np.ndarray:
        try:
            return self.values[:, self.columns.index(column)]
        except ValueError:
            raise KeyError(f"{column!r} not recorded; columns: {self.columns}") from None

    def vector(self, prefix: str) -> np.ndarray:
        """All columns of an array port, e.g. ``vector("plant.x")`` -> shape ``(len(time), n)``."""
        names = [c for c in self.columns if c == prefix or c.startswith(prefix + "[")]
        if not names:
            raise KeyError(f"{prefix!r} not recorded; columns: {self.columns}")
        return np.column_stack([self[c] for c in names])

    def index_at(self, t: float) -> int:
        """Index of the communication point nearest to ``t``."""
        return int(np.argmin(np.abs(self.time - t)))

    def sampled(self, interval: float) -> "Result":
        """The rows nearest to ``t0, t0 + interval, ...`` and the last one (for smaller files)."""
        targets = np.append(np.arange(self.time[0], self.time[-1], interval), self.time[-1])
        right = np.clip(np.searchsorted(self.time, targets), 1, len(self.time) - 1)
        nearer_left = targets - self.time[right - 1] <= self.time[right] - targets
        rows = np.unique(np.where(nearer_left, right - 1, right))
        return Result(self.time[rows], list(self.columns), self.values[rows], self.interrupted)

    def to_csv(self, path: Path | str) -> None:
        header = ",".join(["time"] + self.columns)
        data = np.column_stack([self.time, self.values])
        np.savetxt(path, data, delimiter=",", header=header, comments="", fmt="%.17g")

    @classmethod
    def from_csv(cls, path: Path | str) -> "Result":
        with open(path) as handle:
            columns = handle.readline().strip().split(",")
        data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
        return cls(data[:, 0], columns[1:], data[:, 1:])
