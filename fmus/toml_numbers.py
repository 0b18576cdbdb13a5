"""Integers a TOML file may hold but a float cannot: found before anything converts them.

TOML integers are unbounded (Python's ``int``); ``float()`` of one with 309 digits or more raises
``OverflowError``, which ended a design or campaign file with a traceback (issue 37.6).  The system
files check each number where they read it (:mod:`fmus.system.values`); the design and campaign files
ask :func:`huge_integer` of the whole parsed file once.
"""

from __future__ import annotations

__all__ = ["LARGEST", "huge_integer"]

#: the largest float, as an integer: every integer beyond it is beyond a float
LARGEST = int(float.fromhex("0x1.fffffffffffffp+1023"))


def huge_integer(value, key: str = "") -> str | None:
    """``"KEY: an integer of N digits is beyond the range of a float (about 1.8e308)"`` for the first such integer
    in ``value`` (tables, arrays and scalars, as :mod:`tomllib` returns them; KEY dotted, arrays ``[i]`` from
    1), or None."""
    if isinstance(value, dict):
        items = ((f"{key}.{name}" if key else str(name), item) for name, item in value.items())
    elif isinstance(value, list):
        items = ((f"{key}[{index}]", item) for index, item in enumerate(value, start=1))
    else:
        if isinstance(value, int) and not isinstance(value, bool) and abs(value) > LARGEST:
            return f"{key}: an integer of {len(str(abs(value)))} digits is beyond the range of a float (about 1.8e308)"
        return None
    for name, item in items:
        found = huge_integer(item, name)
        if found:
            return found
    return None
