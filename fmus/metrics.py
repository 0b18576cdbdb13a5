"""Small measurements on recorded signals, shared by the scenario summaries and tests."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["time_to_stay_below", "settling_time", "format_time", "NOT_REACHED"]

NOT_REACHED = "not reached"  #: how a time that never came (``inf``) is written


def time_to_stay_below(time: np.ndarray, error: np.ndarray, tolerance: float) -> float:
    """First time after which ``|error|`` (max over columns) stays below ``tolerance``; ``inf`` if never."""
    magnitude = np.abs(np.asarray(error, dtype=float))
    if magnitude.ndim > 1:
        magnitude = magnitude.max(axis=1)
    above = np.nonzero(~(magnitude < tolerance))[0]
    if above.size == 0:
        return float(time[0])
    if above[-1] == len(time) - 1:
        return float("inf")
    return float(time[above[-1] + 1])


def settling_time(time: np.ndarray, signal: np.ndarray, band: float = 0.05) -> float:
    """Time after which ``|signal|`` stays within ``band`` times its peak (decay to zero)."""
    magnitude = np.abs(np.asarray(signal, dtype=float))
    if magnitude.ndim > 1:
        magnitude = magnitude.max(axis=1)
    return time_to_stay_below(time, magnitude, band * magnitude.max())


def format_time(value: float, unit: str = "s", digits: int = 3) -> str:
    """``1.234 s``; :data:`NOT_REACHED` for ``inf`` (a time that never came during the run)."""
    return f"{value:.{digits}f} {unit}" if math.isfinite(value) else NOT_REACHED
