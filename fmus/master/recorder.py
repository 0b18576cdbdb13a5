"""Where the communication points of a run go: :class:`Recorder`, :class:`MemoryRecorder` (a :class:`Result`)."""

from __future__ import annotations

import numpy as np

from ..result import Result

__all__ = ["Recorder", "MemoryRecorder"]


class Recorder:
    """Receives the communication points of a run, ``t0`` included, in order.

    Subclass it to stream rows somewhere (a file, a reduced metric) instead
    of keeping them: :meth:`begin` gets the column names
    (``instance.variable``), :meth:`record` each point (``values`` is only
    valid during the call: copy what you keep), :meth:`result` is what
    :meth:`Session.run` returns.
    """

    def begin(self, columns: list[str]) -> None:
        self.columns = list(columns)

    def record(self, t: float, values: np.ndarray) -> None:
        raise NotImplementedError

    def result(self):
        raise NotImplementedError


class MemoryRecorder(Recorder):
    """Keeps every point in memory (a table that doubles when full) and returns a :class:`Result`."""

    def begin(self, columns: list[str]) -> None:
        super().begin(columns)
        self._count = 0
        self._table = np.empty((1024, len(self.columns) + 1))

    def record(self, t: float, values: np.ndarray) -> None:
        if self._count == len(self._table):
            self._table = np.concatenate([self._table, np.empty_like(self._table)])
        row = self._table[self._count]
        row[0] = t
        row[1:] = values
        self._count += 1

    def result(self) -> Result:
        table = self._table[:self._count]
        return Result(table[:, 0].copy(), list(self.columns), table[:, 1:].copy())
