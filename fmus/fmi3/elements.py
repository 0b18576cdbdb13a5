"""FMI 2.0 element names over the variables of an FMI 3.0 FMU.

Everything outside the FMUs -- connections (``plant.x[1] -> observer.y``), ``--set plant.x0[1]=0.1``,
result columns (``observer.x_hat[2]``) -- names array elements the FMI 2.0 way.  For an FMI 3.0 FMU
each such name is one element of an FMI 3.0 variable: ``x_hat[2]`` is element 1 (row-major, from 0)
of the array ``x_hat``; a scalar variable is its own single element.  :func:`elements` gives that
map for a model description read by fmpy, so the master, the exports and the tests handle FMI 2.0
and FMI 3.0 FMUs of one definition with the same names.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..runtime.definition import element_names

__all__ = ["Element", "elements", "scalar_variables", "units_note", "element_units"]

#: FMI 3.0 type -> the FMI 2.0 type the rest of the project speaks
_TYPES = {"Float64": "Real", "Int32": "Integer", "Boolean": "Boolean", "String": "String"}


@dataclass(frozen=True)
class Element:
    """One element (FMI 2.0 name) of an FMI 3.0 variable."""

    name: str               #: FMI 2.0 name: ``x_hat[2]``, ``u``
    variable: str           #: FMI 3.0 variable: ``x_hat``
    index: int              #: row-major position in the variable, from 0
    size: int               #: number of elements of the variable
    valueReference: int     #: the FMI 3.0 variable's value reference
    type: str               #: ``"Real"`` or ``"Integer"`` (FMI 2.0 type names)
    causality: str
    variability: str
    start: str | None       #: this element's start value (text), if any
    min: str | None = None
    max: str | None = None
    unit: str | None = None
    description: str | None = None


#: how an FMI 3.0 array of elements with different units says them (FMI 3.0 gives a variable one unit)
_UNITS_NOTE = " (units by element: "


def units_note(description: str, units) -> str:
    """``description`` with the units of the elements of a mixed-unit array: ``... (units by element: A, rad)``."""
    return f"{description}{_UNITS_NOTE}{', '.join(unit or '-' for unit in units)})"


def element_units(description: str | None, size: int) -> list[str | None] | None:
    """The units :func:`units_note` wrote into ``description``, one per element (None: no such note)."""
    if not description or not description.endswith(")") or _UNITS_NOTE not in description:
        return None
    units = [unit.strip() for unit in description[description.rindex(_UNITS_NOTE) + len(_UNITS_NOTE):-1].split(",")]
    return [None if unit == "-" else unit for unit in units] if len(units) == size else None


def elements(model_description) -> dict[str, Element]:
    """FMI 2.0 element name -> :class:`Element` for every variable except ``time`` (in document order)."""
    found = {}
    for variable in model_description.modelVariables:
        if variable.causality == "independent":
            continue
        shape = tuple(int(d.start) for d in variable.dimensions)
        names = element_names(variable.name, shape)
        starts = variable.start.split() if variable.start else [None] * len(names)
        units = element_units(variable.description, len(names)) or [variable.unit] * len(names)
        for index, name in enumerate(names):
            found[name] = Element(name, variable.name, index, len(names), variable.valueReference,
                                  _TYPES.get(variable.type, variable.type), variable.causality, variable.variability,
                                  starts[index] if index < len(starts) else None, variable.min, variable.max,
                                  units[index], variable.description)
    return found


def scalar_variables(fmu) -> list:
    """The variables of ``fmu`` by FMI 2.0 name: an FMI 2.0 FMU's own, an FMI 3.0 FMU's elements.

    Both have ``name``, ``type`` (FMI 2.0 names), ``causality``, ``variability``, ``start``, ``min``,
    ``max``, ``unit`` and ``description``.
    """
    from fmpy import read_model_description

    description = read_model_description(str(fmu), validate=False)
    if description.fmiVersion.startswith("3"):
        return list(elements(description).values())
    return [v for v in description.modelVariables]
