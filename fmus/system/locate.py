"""Line numbers of a TOML file's tables and keys (:mod:`tomllib` gives none), for the messages.

:class:`Locator` scans the raw text once: the headers ``[a.b]`` and ``[[a.b]]`` (numbered from 1 as
``a.b[1]``) and the keys ``k = ...`` under them.  :meth:`Locator.line` finds the line of a dotted
field name (``components.plant.A``), else of its nearest enclosing table; :meth:`Locator.string` finds
where a string value starts (an expression's line and column).
"""

from __future__ import annotations

import re

__all__ = ["Locator"]

_PART = r'(?:"[^"\n]*"|\'[^\'\n]*\'|[A-Za-z0-9_-]+)'
_DOTTED = rf"{_PART}(?:\s*\.\s*{_PART})*"
_HEADER = re.compile(rf"\s*(\[\[?)\s*({_DOTTED})\s*\]\]?")
_KEY = re.compile(rf"\s*({_DOTTED})\s*=")
_INDEX = re.compile(r"\[\d+\]")
_STRING = re.compile(r'"(?:[^"\\\n]|\\.)*"')


def _parts(dotted: str) -> list[str]:
    return [part.strip().strip("\"'") for part in re.findall(_PART, dotted)]


class Locator:
    """Where the tables and keys of ``text`` are (1-based lines; offsets into ``text``)."""

    def __init__(self, text: str):
        self.text = text
        self.places: dict[str, tuple[int, int]] = {}    # dotted name -> (line, offset of the line)
        counts: dict[str, int] = {}
        table: list[str] = []
        offset = 0
        for number, line in enumerate(text.split("\n"), start=1):
            header, key = _HEADER.match(line), _KEY.match(line)
            if header:
                table = _parts(header[2])
                if header[1] == "[[":
                    name = ".".join(table)
                    counts[name] = counts.get(name, 0) + 1
                    table = table[:-1] + [f"{table[-1]}[{counts[name]}]"]
                self.places.setdefault(".".join(table), (number, offset))
            elif key:
                self.places.setdefault(".".join(table + _parts(key[1])), (number, offset))
            offset += len(line) + 1

    def line(self, name: str) -> int | None:
        """The line of ``name`` or of the nearest enclosing table or key that has one; None if none."""
        parts = name.split(".")
        while parts:
            for candidate in (".".join(parts), _INDEX.sub("", ".".join(parts))):
                if candidate in self.places:
                    return self.places[candidate][0]
            parts.pop()
        return None

    def item_line(self, name: str, index: int) -> int | None:
        """The line of the ``index``-th (from 1) string of the list written at key ``name``."""
        place = self.places.get(name)
        if place is None:
            return None
        for number, match in enumerate(_STRING.finditer(self.text, place[1]), start=1):
            if number == index:
                return self.text.count("\n", 0, match.start()) + 1
        return place[0]

    def string(self, name: str, value: str, after: int = 0) -> tuple[int, int, int] | None:
        """``(line, column, end offset)`` of the string ``value`` written at or after key ``name`` (and
        ``after``): column of its first character inside the quotes.  None if not written plainly."""
        place = self.places.get(name)
        if place is None:
            return None
        start = max(place[1], after)
        for quote in ('"', "'", '"""', "'''"):
            found = self.text.find(quote + value + quote, start)
            if found >= 0:
                first = found + len(quote)
                line = self.text.count("\n", 0, first) + 1
                column = first - (self.text.rfind("\n", 0, first) + 1) + 1
                return line, column, first + len(value)
        return None
