"""Worker processes that die with the process that started them (``obsfmu all|report --jobs``, sweeps).

A parent killed with SIGKILL runs no cleanup: its workers (and multiprocessing's resource tracker,
which lives as long as any of them holds its pipe) used to go on under PID 1, writing into the output
folder for half a minute and then idling at 120-150 MB each.  :func:`die_with_parent`, called first
thing in a worker, makes sure they do not:

* on Linux the kernel sends the worker SIGKILL when its parent dies (``prctl(PR_SET_PDEATHSIG)``:
  immediate, even while the worker runs an FMU's C code);
* everywhere a daemon thread looks every :data:`POLL` seconds whether the parent is still its parent
  (``os.getppid()`` changes when it dies) and ends the process if not;
* a parent already gone before the worker got here ends it at once.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading
import time

__all__ = ["die_with_parent", "POLL"]

POLL = 0.5            #: seconds between two looks of the watchdog thread at the parent
_PR_SET_PDEATHSIG = 1


def die_with_parent(parent: int) -> None:
    """End this process when ``parent`` (its parent's pid, as the parent saw itself) is gone."""
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):
            pass                                   # the watchdog below still holds
    if os.getppid() != parent:                     # died before prctl: nobody will send the signal
        os._exit(1)
    threading.Thread(target=_watch, args=(parent,), name="obsfmu-parent-watch", daemon=True).start()


def _watch(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(POLL)
    os._exit(1)
