"""Ctrl-C, SIGTERM and SIGHUP: inside a run they stop it after the current communication step
(:class:`StopRequest`); elsewhere they unwind the command as Ctrl-C does (:class:`Terminated`).
The exit code is 128 + the signal (130, 143, 129)."""

from __future__ import annotations

import os
import signal
import sys
import threading

__all__ = ["StopRequest", "Terminated", "interrupted_status", "install_handlers", "restore_handlers",
           "raise_terminated", "STOP_SIGNALS", "EXIT_INTERRUPTED"]

EXIT_INTERRUPTED = 130  #: 128 + SIGINT, what a shell reports for a Ctrl-C
#: the signals that stop a command cleanly: Ctrl-C, what timeout / CI / batch schedulers send, a closed terminal
STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP outside a run: unwinds the command as Ctrl-C's KeyboardInterrupt does."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def interrupted_status(exc: KeyboardInterrupt) -> int:
    """The exit code of a command stopped by ``exc``: 128 + its signal (130 for Ctrl-C)."""
    return 128 + getattr(exc, "signum", signal.SIGINT)


def install_handlers(handler, signals=STOP_SIGNALS) -> dict:
    """Install ``handler`` for ``signals`` (main thread only), except SIGTERM / SIGHUP when ignored
    (``nohup``); returns the previous handlers for :func:`restore_handlers`."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    return {number: signal.signal(number, handler) for number in signals
            if number == signal.SIGINT or signal.getsignal(number) is not signal.SIG_IGN}


def restore_handlers(previous: dict) -> None:
    for number, handler in previous.items():
        signal.signal(number, handler)


def raise_terminated(signum, frame):
    raise Terminated(signum)


class StopRequest:
    """While active, SIGINT, SIGTERM and SIGHUP only set a flag (the master asks it after every
    communication point); :attr:`exit_code` is then 128 + the signal.

    The FMUs run Python code in this interpreter, so no exception may be raised inside them.  A
    second signal kills the process at once (it leaves only hidden temporary files behind).
    """

    def __init__(self, quiet: bool = False, shared=None):
        self.requested = False
        self.signum = signal.SIGINT  # the signal that asked (SIGINT also when another process asked)
        self.quiet = quiet      # no message (a worker process of 'obsfmu all --jobs N')
        self.shared = shared    # a shared byte (multiprocessing RawValue) another process may set
        self._previous: dict = {}

    def __call__(self) -> bool:
        return self.requested or bool(self.shared is not None and self.shared.value)

    @property
    def exit_code(self) -> int:
        return 128 + self.signum

    def _handle(self, signum, frame) -> None:
        if self.requested:
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
            return
        self.requested, self.signum = True, signum
        if not self.quiet:
            again = "Ctrl-C" if signum == signal.SIGINT else signal.Signals(signum).name
            print(f"\nobsfmu: stopping after the current step ({again} again to kill at once)", file=sys.stderr,
                  flush=True)

    def __enter__(self) -> "StopRequest":
        self._previous = install_handlers(self._handle)
        return self

    def __exit__(self, *exc) -> None:
        restore_handlers(self._previous)
