"""Small measurements on recorded signals, shared by the scenario summaries and tests."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["time_to_stay_below", "settling_time", "format_time", "fluctuation", "NOT_REACHED", "HOLD"]

NOT_REACHED = "not reached"  #: how a time that never came (``inf``) is written

#: the last fraction of a run: a sample converged when its error stayed within tolerance from its convergence time
#: to the end for at least this fraction of the run (an error that dips below the tolerance at the very end, noise,
#: is no convergence: issue 38's "4 of 4 converged" at 2.998 s of a 3 s run); :func:`fluctuation` looks at it too
HOLD = 0.1


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


def fluctuation(time: np.ndarray, error: np.ndarray, fraction: float = HOLD) -> float:
    """The standard deviation of ``error`` about its quadratic trend over the last ``fraction`` of the run.

    What a noisy measurement leaves in an estimate and no convergence removes: ``3 * fluctuation`` above a
    tolerance means the error cannot stay within it, however long the run.  A smooth decay or drift over the
    window has almost none (a quadratic follows it); a limit cycle or chattering counts like noise.
    """
    time, error = np.asarray(time, dtype=float), np.asarray(error, dtype=float)
    window = time >= time[-1] - fraction * (time[-1] - time[0])
    if np.count_nonzero(window) < 5 or not np.all(np.isfinite(error[window])):
        return math.nan
    t = (time[window] - time[window].mean()) / max(np.ptp(time[window]), 1e-300)
    trend = np.polynomial.polynomial.polyfit(t, error[window], 2)
    return float(np.std(error[window] - np.polynomial.polynomial.polyval(t, trend)))
