"""What goes wrong in a co-simulation: :class:`SimulationError`, raised naming the instance and what its FMU logged."""

from __future__ import annotations

import difflib

__all__ = ["SimulationError", "WARNING", "closest", "call", "check"]

WARNING = 1  #: worst FMI status that lets a run go on
_STATUS_WORDS = ("ok", "warning", "discard", "error", "fatal", "pending")


class SimulationError(RuntimeError):
    """A co-simulation could not be set up or an FMU refused a step."""


def closest(name: str, candidates) -> str:
    """``"; did you mean ...?"`` with the candidates closest to ``name``, or nothing."""
    close = difflib.get_close_matches(name, list(candidates), n=3)
    return f"; did you mean {', '.join(close)}?" if close else ""


def call(inst, logger, what: str, function, *args):
    """``function(*args)``; an exception becomes a :class:`SimulationError` naming ``inst`` and ``what``."""
    try:
        return function(*args)
    except Exception as exc:
        raise SimulationError(f"{inst.name}: {what} failed ({exc}); FMU says: {logger.last(inst.name)}") from None


def check(inst, logger, what, status: int) -> None:
    """Raise :class:`SimulationError` for a status worse than warning (``what`` may be a callable)."""
    if status > WARNING:
        word = _STATUS_WORDS[status] if 0 <= status < len(_STATUS_WORDS) else str(status)
        what = what() if callable(what) else what
        raise SimulationError(f"{inst.name}: {what} failed (status {status} ({word})); "
                              f"FMU says: {logger.last(inst.name)}")
