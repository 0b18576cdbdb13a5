"""The FMUs' log messages of a session: kept, warnings and errors echoed to stderr."""

from __future__ import annotations

import sys

from fmpy import calloc, free
from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                       fmi2CallbackLoggerTYPE)

__all__ = ["Logger"]

_STATUS = ["OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING"]


class Logger:
    """Collects FMU log messages; echoes warnings and errors to stderr.

    :attr:`callbacks` are the FMI 2.0 callbacks; an FMI 3.0 instance passes its messages to :meth:`log`.
    """

    def __init__(self, echo: bool):
        self.messages: list[tuple[str, str, str]] = []
        self.echo = echo
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self.log)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        # no fmpy logger proxy: it keeps one global Python logger, which a later run would leave
        # dangling for every other FMU in the process.  obsfmu's binary passes the finished message
        # as the format string (with '%' doubled), so no variadic arguments are needed.

    def log(self, component, instance: bytes, status: int, category, message: bytes) -> None:
        """One message (the arguments of the FMI 2.0 logger callback)."""
        entry = (instance.decode(errors="replace"), _STATUS[status] if status < 6 else str(status),
                 message.decode(errors="replace").replace("%%", "%"))
        self.messages.append(entry)
        if self.echo and status >= 1:
            print(f"[{entry[1]}] {entry[0]}: {entry[2]}", file=sys.stderr)

    def note(self, message: str) -> None:
        """A message of the master itself (instance ``master``), echoed to stderr."""
        self.messages.append(("master", "OK", message))
        if self.echo:
            print(f"[note] master: {message}", file=sys.stderr)

    def last(self, instance: str, count: int = 3) -> str:
        """The last ``count`` messages of ``instance``, joined, or ``"no message logged"``."""
        mine = [m for i, _, m in (e for e in self.messages) if i == instance]
        return " | ".join(mine[-count:]) if mine else "no message logged"
