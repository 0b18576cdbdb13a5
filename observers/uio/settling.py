r"""When has an asymptotically converging estimate converged?  A test that needs no true value.

Stages 2-4 of paper 003 regress on signals that are exact only up to
decaying filter transients, so their finite-time DREM switch (``nu < mu``)
does not mean the estimate is exact (it is far off at that time, see
``docs/paper003.md``).  A stage is declared *identified* at the first time
``T`` such that

* its FT-DREM has switched (``nu_i < mu`` for every ``i``) and the stages it
  depends on are identified, and
* over the last ``window`` seconds the estimate stayed within
  ``tol * (1 + |reference|)`` (max norm) of its value at the start of that
  window.

Status 1.  If that has not happened ``timeout`` seconds after the stage
started, the stage is stopped anyway (status 2): the information of stage 2
(``xi(0)``) is in the plant's transient only, so with measurement noise the
estimate would otherwise wander for ever and the later stages never start.
The decision is latched; the observer stops adapting an identified stage.  A
stage stopped at the timeout keeps the moving average of its estimate over
about ``window`` seconds (:attr:`SettlingDetector.average`): with noisy data
the high-gain laws follow the noise, the average is the better value.
"""

from __future__ import annotations

import numpy as np

from obsfmu.observers.checks import require_positive

__all__ = ["SettlingDetector", "RUNNING", "SETTLED", "TIMED_OUT"]

RUNNING, SETTLED, TIMED_OUT = 0, 1, 2


class SettlingDetector:
    """Latching detector of a settled estimate (see module docstring).

    Parameters
    ----------
    tol : float
        Relative tolerance > 0.
    window : float
        Length of the quiet interval, s (>= 0).
    timeout : float
        Stop the stage this long after ``start``, s (> 0).
    start : float
        Time the stage starts.

    Attributes
    ----------
    status : int
        ``RUNNING`` (0), ``SETTLED`` (1) or ``TIMED_OUT`` (2).
    time : float or None
        When the status left ``RUNNING``.
    """

    not_state = ("tol", "window", "timeout")
    state_optional = {"reference": None, "time": None, "average": None, "_last_t": None}

    def __init__(self, tol: float, window: float, timeout: float, start: float = 0.0):
        self.tol = require_positive("settle_tol", tol)
        self.window = require_positive("settle_window", window, allow_zero=True)
        self.timeout = require_positive("t_identify", timeout)
        self.start = float(start)
        self.reference: np.ndarray | None = None
        self.since = self.start
        self.status = RUNNING
        self.time: float | None = None
        self.average: np.ndarray | None = None      # moving average, time constant ``window``
        self.average_kept = False                   # set by the owner once it froze the stage at it
        self._last_t: float | None = None

    @property
    def done(self) -> bool:
        return self.status != RUNNING

    def update(self, t: float, estimate: np.ndarray, ready: bool) -> None:
        """Feed the estimate at time ``t``; ``ready``: switched and prerequisites identified."""
        if self.done:
            return
        estimate = np.asarray(estimate, dtype=float)
        self._track_average(t, estimate)
        moved = (self.reference is None or
                 np.max(np.abs(estimate - self.reference)) > self.tol * (1.0 + np.max(np.abs(self.reference))))
        if not ready or moved:
            self.reference, self.since = estimate.copy(), t
        elif t - self.since >= self.window:
            self.status, self.time = SETTLED, t
            return
        if t - self.start >= self.timeout - 1e-9 * max(1.0, abs(t)):  # a host summing t += h lands just below
            self.status, self.time = TIMED_OUT, t

    def _track_average(self, t: float, estimate: np.ndarray) -> None:
        """Moving average of the estimate with time constant ``window`` (the value kept at a timeout)."""
        if self.average is None or self.window == 0.0:
            self.average = estimate.copy()
        else:
            weight = -np.expm1(-(t - self._last_t) / self.window)
            self.average = self.average + weight * (estimate - self.average)
        self._last_t = t
