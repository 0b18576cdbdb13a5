"""The fixed-step loop, and what every stepping loop shares (:class:`Loop`: recording, stopping, progress)."""

from __future__ import annotations

import os
import sys

import numpy as np
from tqdm import tqdm

from .recorder import Recorder
from .round import Stepper

__all__ = ["Loop", "Progress", "communication_points", "fixed"]


def _terminal_columns(stream) -> int:
    """The columns of the terminal ``stream`` writes to (0: none, or a terminal that does not say)."""
    try:
        return os.get_terminal_size(stream.fileno()).columns
    except (OSError, ValueError, AttributeError):
        return 0


class Progress:
    """The run's progress in model time on stderr (tqdm), shown only for runs longer than a second."""

    def __init__(self, enabled: bool, start_time: float, stop_time: float, time_unit: str = "s"):
        self.enabled, self.start_time = enabled, start_time
        # a pseudo-terminal may report a size of 0 x 0 (script, pty.fork, CI runners): tqdm then draws nothing at
        # all, so such a terminal gets 100 x 20 (issue 38: no bar seen on a 6 s run in a pseudo-terminal)
        sized = _terminal_columns(sys.stderr) > 0
        self.bar = tqdm(total=stop_time - start_time, disable=not enabled, file=sys.stderr, delay=1.0,
                        mininterval=0.2, unit=time_unit, leave=True, dynamic_ncols=sized,
                        ncols=None if sized else 100, nrows=None if sized else 20,
                        bar_format="{l_bar}{bar:30}| t = {n:.4g}/{total:.4g} {unit}{postfix} [{elapsed}<{remaining}]")

    def update(self, t: float, steps: int) -> None:
        if self.enabled:
            self.bar.n = t - self.start_time
            self.bar.update(0)           # tqdm draws when due (after the first second, every 0.2 s)

    def close(self, steps: int) -> None:
        if self.enabled:
            self.bar.set_postfix_str(f"{steps} steps", refresh=False)
        self.bar.close()


class Loop:
    """What every stepping loop shares: recording, the stop request (``should_stop``: None for none) and the
    progress bar.  Called once per communication point: what no one asked for (no stop request, no bar)
    costs no call there."""

    def __init__(self, recorder: Recorder, should_stop, progress: Progress):
        self.recorder, self.should_stop, self.progress = recorder, should_stop, progress
        self.steps = 0
        self.interrupted = False
        self._update = progress.update if progress.enabled else None

    def record(self, t: float, values: np.ndarray) -> None:
        self.recorder.record(t, values)

    def accepted(self, t: float) -> bool:
        """Count an accepted step ending at ``t``; False when the run must stop here."""
        self.steps += 1
        if self._update is not None:
            self._update(t, self.steps)
        if self.should_stop is not None and self.should_stop():
            self.interrupted = True
            return False
        return True


def communication_points(start_time: float, stop_time: float, step: float, ramp: int = 0):
    """The steps of a fixed-step run, ``(t, h, t_next)``, generated as they come (bounded memory).

    The grid ``start_time + k step`` (the last step shortened to land on ``stop_time``); with
    ``ramp = r`` the first step is split into ``h/2^r, h/2^r, h/2^(r-1), ..., h/2`` (see
    :func:`fmus.master.cosimulate`).  Every length is ``step`` times a power of two, so the FMUs'
    cached discretisations are reused, and the ramp ends exactly on the grid.
    """
    steps = int(np.ceil((stop_time - start_time) / step - 1e-9))
    for k in range(steps):
        t, t_next = start_time + step * k, min(start_time + step * (k + 1), stop_time)
        h = step if k < steps - 1 else t_next - t  # one step length: cached discretisations
        if k == 0 and ramp > 0:
            offset = 0.0
            for j in [ramp] + list(range(ramp, 0, -1)):
                yield t + offset, h * 2.0 ** -j, t + (offset + h * 2.0 ** -j)
                offset += h * 2.0 ** -j
            continue
        yield t, h, t_next


def fixed(stepper: Stepper, start_time: float, stop_time: float, step: float, loop: Loop, ramp: int = 0) -> None:
    """The fixed-step run: one round per communication point, each recorded."""
    step_round, record, accepted, live = stepper.round, loop.recorder.record, loop.accepted, stepper.live
    for t, h, t_next in communication_points(start_time, stop_time, step, ramp):
        step_round(t, h)
        record(t_next, live)            # ``live`` is never rebound: the instances write into views of it
        if not accepted(t_next):
            return
