"""The component types of a system file: a registry ``kind -> ComponentType``.

A :class:`ComponentType` lists its :class:`Field` s (name, type, default or required, unit, one-line
doc, example) and a ``define`` function that turns the checked field values of one component into its
FMU definitions (:class:`~fmus.runtime.definition.FmuDefinition`) through the definition functions of
:mod:`fmus.runtime.kinds`.  The definitions carry the component's ports, so connections are checked
against them before anything is built.  The types themselves are registered by
:mod:`fmus.system.linear_types` and :mod:`fmus.system.signal_types` (both imported by
:mod:`fmus.system.kinds`, which also generates the field reference of ``docs/system-file-reference.md``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Field", "ComponentType", "Context", "REQUIRED", "TYPES", "register", "FIELD_TYPES", "COMMON_FIELDS"]


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


REQUIRED: Any = _Required()   #: the default of a field that must be given

#: the value types a field may have, with how the reference describes them
FIELD_TYPES = {
    "number": "a finite number",
    "integer": "a whole number",
    "boolean": "true or false",
    "string": "a text without control characters",
    "choice": "one of the texts listed",
    "vector": "a list of finite numbers",
    "matrix": "a list of rows of one length, each entry a finite number or a constant expression (`\"-16000/250\"`, `\"2*pi\"`)",
    "poles": "a list of poles: numbers, or [re, im] pairs for complex ones",
    "units": "a unit (text), or a list of units, one per entry",
    "names": "a list of distinct names (texts), one per entry",
    "expressions": "a list of expressions (texts, one per entry; see the expression language)",
    "expression": "one expression (a text), or a number",
    "expression-vector": "a list of expressions (texts) or numbers, one per entry",
    "expression-matrix": "a list of rows, each a list of expressions (texts) or numbers, all rows of one length",
    "expression-or-vector": "one expression (a text) or number, or a list of them (one per entry)",
    "vector-or-matrix": "a list of finite numbers, or a list of rows (a matrix)",
    "table": "a table of name = number",
    "unit-table": "a table of name = unit (text)",
    "component": "the name of another component of the file",
    "connections": 'a list of texts "a.y -> b.u"',
}


@dataclass(frozen=True)
class Field:
    """One field of a component type (or of a section of the file)."""

    name: str
    type: str
    doc: str
    default: Any = REQUIRED
    unit: str = ""
    example: str = ""
    choices: tuple[str, ...] = ()
    maximum: int | None = None      #: the largest value an integer field takes (a size: the design limit)

    def __post_init__(self):
        if self.type not in FIELD_TYPES:
            raise ValueError(f"field {self.name}: unknown type {self.type!r}")

    @property
    def required(self) -> bool:
        return self.default is REQUIRED


@dataclass
class Context:
    """What a ``define`` function may know beyond its own fields.

    ``prefix`` names the component in messages (``components.plant.``); ``name`` is the system's,
    ``time_unit`` its unit of time;
    ``others`` maps every component defined before this one to its ``(kind, values)``; ``folder`` is the
    system file's folder (relative paths are read from there); ``notes`` collects what the build prints
    (designed gains and poles); ``rates`` the fastest rates of the components' dynamics and signals
    (``(|lambda| in 1/time unit, what)``), against which every run's step is checked; ``stop_time`` and
    ``step`` are the experiment's.
    """

    prefix: str
    name: str = ""
    time_unit: str = "s"
    others: dict[str, tuple[str, dict]] = field(default_factory=dict)
    folder: Path = Path(".")
    notes: list[str] = field(default_factory=list)
    stop_time: float | None = None     #: the file's [experiment] stop_time (checks on a grid of [0, stop_time])
    step: float | None = None          #: the file's [experiment] step (the in-memory runs, fmus.system.inmemory)
    rates: list[tuple[float, str]] = field(default_factory=list)

    def rate(self, eigenvalues, what: str) -> None:
        """Record the largest ``|eigenvalue|`` (or angular frequency) of ``eigenvalues`` as the rate of ``what``."""
        values = np.abs(np.atleast_1d(np.asarray(eigenvalues, dtype=complex)))
        if values.size and np.all(np.isfinite(values)) and values.max() > 0:
            self.rates.append((float(values.max()), f"{self.prefix}{what}"))


@dataclass(frozen=True)
class ComponentType:
    """A kind of component: its fields and ``define(model_name, values, context) -> [FmuDefinition]``.

    ``values`` holds every field (the defaults filled in) and the key ``"given"``: the names of the
    fields the file gave.  ``depends``: the fields that name another component (defined first).
    """

    kind: str
    doc: str
    fields: tuple[Field, ...]
    define: Callable[[str, dict, Context], list]
    depends: tuple[str, ...] = ()

    def field(self, name: str) -> Field | None:
        return next((f for f in self.fields if f.name == name), None)


#: fields every component has
COMMON_FIELDS = (
    Field("kind", "string", "the component's type (the headings of this reference)", example='"lti"'),
    Field("description", "string", "one line for the FMU's description (default: the type's formula)", "",
          example='"DC motor"'),
)

TYPES: dict[str, ComponentType] = {}


def register(kind: str, doc: str, fields, define, depends=()) -> ComponentType:
    """Add the component type ``kind``; its fields follow the common ones (kind, description)."""
    if kind in TYPES:
        raise RuntimeError(f"component type {kind!r} registered twice")
    TYPES[kind] = ComponentType(kind, doc, COMMON_FIELDS + tuple(fields), define, tuple(depends))
    return TYPES[kind]
