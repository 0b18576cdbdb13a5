"""What one varied variable takes: a grid, a list, or a random distribution.

The grammar (parsed with regular expressions, never ``eval``)::

    spec    := grid | list | random
    grid    := NUMBER ":" NUMBER ":" INTEGER          -3:3:7  ->  7 points from -3 to 3
    list    := "[" NUMBER ("," NUMBER)* "]"           [0.5, 1, 2]
             | NUMBER ("," NUMBER)*                   0.5,1,2
    random  := ("uniform" | "loguniform") "(" NUMBER "," NUMBER ")"   bounds lo < hi
             | "normal" "(" NUMBER "," NUMBER ")"                     mean, standard deviation

Grids and lists are *axes* (the campaign takes their product); random
specs are *draws* (``--samples N`` values from a seeded numpy ``Generator``).
"""

from __future__ import annotations

import re
import zlib
from dataclasses import dataclass

import numpy as np

from .errors import CampaignError

__all__ = ["Grid", "Choice", "Distribution", "Spec", "parse_spec", "spec_from_value", "rng_for"]

_NUMBER = r"[+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|nan|inf|infinity)"
_GRID = re.compile(rf"^\s*({_NUMBER})\s*:\s*({_NUMBER})\s*:\s*([^:\s]+)\s*$", re.IGNORECASE)
_LIST = re.compile(rf"^\s*({_NUMBER}(?:\s*,\s*{_NUMBER})*)\s*$", re.IGNORECASE)
_RANDOM = re.compile(rf"^\s*([a-z]+)\s*\(\s*({_NUMBER})\s*,\s*({_NUMBER})\s*\)\s*$", re.IGNORECASE)
DISTRIBUTIONS = ("uniform", "normal", "loguniform")
#: most points of one grid (a sweep's whole sample limit, fmus.campaign.design.MAX_SAMPLES)
GRID_LIMIT = 1_000_000


def _finite(name: str, text: str, what: str, value: float) -> float:
    if not np.isfinite(value):
        raise CampaignError(f"{name}={text}: {what} must be a finite number, got {value}")
    return value


@dataclass(frozen=True)
class Grid:
    """``count`` evenly spaced points from ``lo`` to ``hi`` (both included)."""

    lo: float
    hi: float
    count: int

    def values(self) -> np.ndarray:
        return np.linspace(self.lo, self.hi, self.count)

    def __str__(self) -> str:
        return f"{self.lo!r}:{self.hi!r}:{self.count}"


@dataclass(frozen=True)
class Choice:
    """An explicit list of values."""

    items: tuple[float, ...]

    def values(self) -> np.ndarray:
        return np.array(self.items, dtype=float)

    def __str__(self) -> str:
        return "[" + ", ".join(repr(v) for v in self.items) + "]"


@dataclass(frozen=True)
class Distribution:
    """``uniform(lo, hi)``, ``loguniform(lo, hi)`` or ``normal(mean, std)``."""

    kind: str
    a: float
    b: float

    def draw(self, rng: np.random.Generator, count: int) -> np.ndarray:
        if self.kind == "uniform":
            return rng.uniform(self.a, self.b, count)
        if self.kind == "loguniform":
            return np.exp(rng.uniform(np.log(self.a), np.log(self.b), count))
        return rng.normal(self.a, self.b, count)

    def __str__(self) -> str:
        return f"{self.kind}({self.a!r}, {self.b!r})"


Spec = Grid | Choice | Distribution


def rng_for(seed: int, name: str) -> np.random.Generator:
    """The generator of variable ``name``: its draws do not depend on the other variables or their order,
    and the first ``N`` of ``N + M`` draws are the ``N`` draws (so ``--samples`` can grow)."""
    return np.random.default_rng([int(seed), zlib.crc32(name.encode())])


def parse_spec(name: str, text: str) -> Spec:
    """Parse the SPEC of ``--vary name=SPEC``; every mistake names the variable and what is wrong."""
    text = str(text).strip()
    if match := _GRID.match(text):
        lo, hi = (_finite(name, text, what, float(v)) for what, v in (("lo", match[1]), ("hi", match[2])))
        try:
            count = int(match[3])
        except ValueError:
            raise CampaignError(f"{name}={text}: the grid's count must be a whole number, got {match[3]!r}") from None
        if count < 1:
            raise CampaignError(f"{name}={text}: the grid's count must be at least 1, got {count}")
        if count > GRID_LIMIT:                 # refused before any array of it exists
            raise CampaignError(f"{name}={text}: {count} grid points, more than a sweep's limit of {GRID_LIMIT} "
                                f"samples; use fewer points")
        if count > 1 and lo == hi:
            raise CampaignError(f"{name}={text}: lo equals hi, so the {count} grid points would coincide")
        if count == 1 and lo != hi:
            raise CampaignError(f"{name}={text}: one point between {lo!r} and {hi!r} is ambiguous; "
                                f"give a single value or count >= 2")
        return Grid(lo, hi, count)
    if match := _RANDOM.match(text):
        kind = match[1].lower()
        if kind not in DISTRIBUTIONS:
            raise CampaignError(f"{name}={text}: unknown distribution {match[1]!r}; use uniform(lo, hi), "
                                f"normal(mean, std) or loguniform(lo, hi)")
        a = _finite(name, text, "the first argument", float(match[2]))
        b = _finite(name, text, "the second argument", float(match[3]))
        if kind == "normal" and not b > 0:
            raise CampaignError(f"{name}={text}: the standard deviation must be positive, got {b!r}")
        if kind != "normal" and not a < b:
            raise CampaignError(f"{name}={text}: the lower bound must be below the upper bound, got {a!r}, {b!r}")
        if kind == "loguniform" and not a > 0:
            raise CampaignError(f"{name}={text}: loguniform needs positive bounds, got lower bound {a!r}")
        return Distribution(kind, a, b)
    bracketed = text.startswith("[") and text.endswith("]")
    if match := _LIST.match(text[1:-1] if bracketed else text):
        items = [_finite(name, text, "every list value", float(v)) for v in match[1].split(",")]
        return _choice(name, text, items)
    raise CampaignError(f"{name}={text}: not a SPEC; expected a grid LO:HI:COUNT (e.g. -3:3:7), a list [a, b, c] "
                        f"or a,b,c, or uniform(lo, hi), normal(mean, std), loguniform(lo, hi)")


def _float(value) -> float:
    """``float(value)``; inf for an integer beyond a float (float() raised OverflowError)."""
    try:
        return float(value)
    except OverflowError:
        return float("inf") if value > 0 else float("-inf")


def _shown(value) -> str:
    text = str(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _choice(name: str, text: str, items: list[float]) -> Choice:
    repeated = sorted({v for v in items if items.count(v) > 1})
    if repeated:
        raise CampaignError(f"{name}={text}: the list repeats {', '.join(repr(v) for v in repeated)}")
    return Choice(tuple(items))


def spec_from_value(name: str, value) -> Spec:
    """A spec from a TOML value: a SPEC string or an array of numbers."""
    if isinstance(value, str):
        return parse_spec(name, value)
    if isinstance(value, (list, tuple)) and value and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                         for v in value):
        items = [_finite(name, _shown(value), "every list value", _float(v)) for v in value]
        return _choice(name, str(value), items)
    raise CampaignError(f"vary.{name}: expected a SPEC string (e.g. \"uniform(0, 1)\", \"-3:3:7\") or an array of "
                        f"numbers, got {value!r}; a fixed value belongs in [set]")
