"""Ctrl-C, SIGTERM and SIGHUP: inside a run they stop it after the current communication step
(:class:`StopRequest`); elsewhere they unwind the command as Ctrl-C does (:class:`Terminated`).
The exit code is 128 + the signal (130, 143, 129), wherever the signal came.

A signal handler's exception surfaces wherever the main thread happens to be, and some places drop it
silently: an object's finalizer (``io`` clears any exception its ``close()`` raises) and C libraries'
callbacks.  fmpy's ``read_model_description`` is both -- lxml's ``except: pass`` around the file's name,
the zip member it never closes, closed by the finalizer -- and the builder reads every FMU it has just
written with it.  So :func:`raise_terminated` remembers the signal until the command reports it
(:func:`interrupted_status`), and :func:`raise_if_terminated` raises it again where the command goes on
to a run or to the next FMU's build (:func:`signals_held`) and where it ends.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from contextlib import contextmanager

__all__ = ["StopRequest", "Terminated", "interrupted_status", "install_handlers", "restore_handlers",
           "raise_terminated", "raise_if_terminated", "signals_held", "STOP_SIGNALS", "EXIT_INTERRUPTED"]

EXIT_INTERRUPTED = 130  #: 128 + SIGINT, what a shell reports for a Ctrl-C
#: the signals that stop a command cleanly: Ctrl-C, what timeout / CI / batch schedulers send, a closed terminal
STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


#: the signal last raised as :class:`Terminated` and not reported yet by :func:`interrupted_status`
_raised: int | None = None


class Terminated(KeyboardInterrupt):
    """Ctrl-C, SIGTERM or SIGHUP outside a run: unwinds the command as Ctrl-C's KeyboardInterrupt does."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def interrupted_status(exc: KeyboardInterrupt) -> int:
    """The exit code of a command stopped by ``exc``: 128 + its signal (130 for Ctrl-C); the interruption is
    reported, :func:`raise_if_terminated` no longer raises it."""
    global _raised
    _raised = None
    return 128 + getattr(exc, "signum", signal.SIGINT)


def install_handlers(handler, signals=STOP_SIGNALS, ignored_too=(signal.SIGINT,)) -> dict:
    """Install ``handler`` for ``signals`` (main thread only), except those ignored (``nohup``, a background
    job's SIGINT) unless in ``ignored_too``; returns the previous handlers for :func:`restore_handlers`."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    return {number: signal.signal(number, handler) for number in signals
            if number in ignored_too or signal.getsignal(number) is not signal.SIG_IGN}


def restore_handlers(previous: dict) -> None:
    for number, handler in previous.items():
        signal.signal(number, handler)


def raise_terminated(signum, frame):
    global _raised
    _raised = signum
    raise Terminated(signum)


def raise_if_terminated() -> None:
    """Raise again the :class:`Terminated` of a signal that some code swallowed (see the module's docstring)."""
    if _raised is not None:
        raise Terminated(_raised)


@contextmanager
def signals_held():
    """Run the block with Ctrl-C, SIGTERM and SIGHUP only noted, then give the first one to the handler that
    was there: for work an exception must not cut halfway (zipfile cut between opening a member and writing
    it raises ValueError over the interruption when closed; a temporary folder's removal cut stays behind)."""
    raise_if_terminated()
    held = []
    previous = install_handlers(lambda signum, frame: held.append(signum))
    try:
        yield
    finally:
        restore_handlers(previous)
        if held:
            signal.raise_signal(held[0])


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

    @property
    def status(self) -> int:
        """0, or :attr:`exit_code` once a stop was asked (also after the last step: the files are completed)."""
        return self.exit_code if self() else 0

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
        raise_if_terminated()   # a signal before the run, lost on the way: the run does not start
        self._previous = install_handlers(self._handle)
        return self

    def __exit__(self, *exc) -> None:
        restore_handlers(self._previous)
