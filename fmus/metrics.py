"""Small measurements on recorded signals, shared by the scenario summaries and tests."""

from __future__ import annotations

import numpy as np

__all__ = ["time_to_stay_below", "settling_time"]


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
