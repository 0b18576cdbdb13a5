"""The campaign's progress bar on stderr: samples done / total, failures so far, ETA."""

from __future__ import annotations

import sys
import time as wallclock

__all__ = ["Progress"]


def _duration(seconds: float) -> str:
    seconds = int(round(seconds))
    if seconds < 60:
        return f"{seconds}s"
    if seconds < 3600:
        return f"{seconds // 60}m{seconds % 60:02d}s"
    return f"{seconds // 3600}h{seconds % 3600 // 60:02d}m"


class Progress:
    """``[#####.....] 12/64 samples (4 from before)  1 failed  eta 2m41s``.

    On a terminal the line is redrawn in place (at most 5 times a second);
    elsewhere (``enabled`` forced on) a plain line is printed at most every
    ``interval`` seconds.  The ETA extrapolates this run's own pace.
    """

    def __init__(self, total: int, before: int, enabled: bool, stream=None, interval: float = 10.0):
        self.total, self.before, self.enabled = total, before, enabled
        self.stream = stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.interval = interval if not self.tty else 0.2
        self.started = wallclock.perf_counter()
        self.last = -float("inf")
        self.done = self.failed = 0

    def line(self) -> str:
        finished = self.before + self.done
        bar = "#" * int(30 * finished / max(self.total, 1))
        elapsed = wallclock.perf_counter() - self.started
        remaining = self.total - finished
        eta = _duration(elapsed / self.done * remaining) if self.done else "?"
        before = f" ({self.before} from before)" if self.before else ""
        return (f"[{bar:<30}] {finished}/{self.total} samples{before}  {self.failed} failed  "
                f"elapsed {_duration(elapsed)}  eta {eta}")

    def update(self, done: int = 0, failed: int = 0, force: bool = False) -> None:
        self.done += done
        self.failed += failed
        now = wallclock.perf_counter()
        if not self.enabled or (not force and now - self.last < self.interval):
            return
        self.last = now
        if self.tty:
            print("\r" + self.line(), end="", file=self.stream, flush=True)
        else:
            print(self.line(), file=self.stream, flush=True)

    def close(self) -> None:
        if self.enabled:
            self.update(force=True)
            if self.tty:
                print(file=self.stream, flush=True)
