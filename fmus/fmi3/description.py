"""The FMI 3.0 ``modelDescription.xml`` of an FMU, from its definition and its slave's FMI 2.0 variables.

The slave (:class:`fmus.runtime.slave.BlockSlave`) is the same for both FMI versions; its variables are
scalars with FMI 2.0 names and value references (``x_hat[1]`` -> 12).  This module groups them
back into the arrays of the definition -- the narrow interface to the slave is its FMI 2.0
description (names and value references), nothing else:

* a parameter ``A`` (naming shape n x n) -> ``<Float64 name="A">`` with two ``<Dimension>``, its
  elements ``A[1,1], A[1,2], ...`` row-major (FMI 3.0 arrays are serialized row-major too);
* a port ``x_hat`` of size n -> ``<Float64 name="x_hat">`` with one ``<Dimension start="n">``;
* a size-one dimension dropped in the FMI 2.0 names (``u``, ``B[i]``) is dropped here too, so a
  scalar stays a scalar and every FMI 2.0 name is ``<FMI 3.0 name>[<indices>]`` or the name itself
  (:func:`fmus.runtime.definition.element_names`);
* ``<port>_interpolation`` -> an Int32 parameter (0 hold, 1 extrapolate, 2 interpolate);
* ``time`` -> the independent variable (value reference 0).

It also writes the table the FMI 3.0 loader reads (``resources/obsfmu_fmi3.txt``): one line per
FMI 3.0 variable, ``<vr> <F|I> <t|p|i|o> <name> <count> <the slave's value references>``.

Units: an array whose elements all have one unit gets it; elements with different units (a plant
state in rad, rad/s, rad/s2) get no ``unit`` and the description lists them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from xml.dom.minidom import parseString
from xml.etree.ElementTree import Element, SubElement, fromstring, tostring

from ..runtime.definition import FmuDefinition, element_names
from .elements import units_note

__all__ = ["Variable", "variables", "describe", "table", "read_table", "CAPABILITIES"]

_FMI2 = {"Real": "Float64", "Integer": "Int32"}
_TABLE_TYPE = {"Float64": "F", "Int32": "I"}
_TABLE_CAUSALITY = {"independent": "t", "parameter": "p", "input": "i", "output": "o"}

#: what the FMI 3.0 loader (fmus/native/loader_fmi3.c) and the slave really support
CAPABILITIES = {
    "needsExecutionTool": "true",  # a Python interpreter with numpy and scipy
    "canBeInstantiatedOnlyOncePerProcess": "false",
    "canGetAndSetFMUState": "true",
    "canSerializeFMUState": "true",
    "providesDirectionalDerivatives": "false",
    "providesAdjointDerivatives": "false",
    "providesPerElementDependencies": "false",
    "maxOutputDerivativeOrder": "0",
    "mightReturnEarlyFromDoStep": "false",
    "canReturnEarlyAfterIntermediateUpdate": "false",
    "hasEventMode": "false",
    "providesEvaluateDiscreteStates": "false",
}


@dataclass
class Variable:
    """One FMI 3.0 variable and the slave's scalar variables it is made of."""

    name: str
    type: str                       #: "Float64" or "Int32"
    causality: str                  #: "independent", "parameter", "input" or "output"
    variability: str
    shape: tuple[int, ...]          #: () for a scalar
    scalars: list[int]              #: the slave's (FMI 2.0) value references, row-major
    description: str | None = None
    start: list[str] | None = None
    units: list[str | None] = field(default_factory=list)
    extra: dict[str, str] = field(default_factory=dict)  #: min/max of the Int32 parameters
    value_reference: int = 0

    @property
    def fmi2_names(self) -> list[str]:
        return element_names(self.name, self.shape)


def _shapes(definition: FmuDefinition) -> dict[str, tuple[tuple[int, ...], str | None]]:
    """Naming shape and description of every array of the definition, by name."""
    shapes = {p.name: (tuple(p.naming_shape), p.description) for p in definition.parameters}
    shapes.update({p.name: (p.naming_shape, p.description) for p in (*definition.inputs, *definition.outputs)})
    return shapes


def variables(definition: FmuDefinition, fmi2_description: bytes) -> list[Variable]:
    """The FMI 3.0 variables (``time`` first) of the FMU whose slave writes ``fmi2_description``."""
    shapes = _shapes(definition)
    groups: dict[str, list[Element]] = {}
    for scalar in fromstring(fmi2_description).iter("ScalarVariable"):
        groups.setdefault(scalar.get("name").split("[")[0], []).append(scalar)
    found = [Variable("time", "Float64", "independent", "continuous", (), [],
                      "simulation time (the independent variable)")]
    for name, scalars in groups.items():
        first = scalars[0]
        kind = next(child for child in first if child.tag in _FMI2)
        shape, description = shapes.get(name, ((), first.get("description")))
        names = [s.get("name") for s in scalars]
        if names != element_names(name, shape):
            raise ValueError(f"{definition.model_name}: the slave's variables {names} are not the elements of "
                             f"{name} with shape {shape}")
        values = [s.find(kind.tag) for s in scalars]
        causality = first.get("causality")
        variable = Variable(name, _FMI2[kind.tag], causality, first.get("variability"), shape,
                            [int(s.get("valueReference")) for s in scalars], description or first.get("description"),
                            units=[v.get("unit") for v in values])
        if causality in ("parameter", "input"):
            variable.start = [_number(v.get("start", "0"), variable.type) for v in values]
        variable.extra = {key: kind.get(key) for key in ("min", "max") if kind.get(key) is not None}
        found.append(variable)
    for reference, variable in enumerate(found):
        variable.value_reference = reference
    return found


def _number(text: str, kind: str) -> str:
    return str(int(text)) if kind == "Int32" else repr(float(text))


def _unit_and_description(variable: Variable) -> tuple[str | None, str | None]:
    units = set(variable.units)
    if len(units) <= 1:
        return (units.pop() if units else None), variable.description
    return None, units_note(variable.description or variable.name, variable.units)


def _variable_element(parent: Element, variable: Variable, intermediate: bool) -> None:
    attributes = {"name": variable.name, "valueReference": str(variable.value_reference)}
    unit, description = _unit_and_description(variable)
    if description:
        attributes["description"] = description
    attributes["causality"] = variable.causality
    attributes["variability"] = variable.variability
    if variable.causality == "output":
        attributes["initial"] = "calculated"
    if variable.causality == "input" and intermediate:
        attributes["intermediateUpdate"] = "true"
    if unit:
        attributes["unit"] = unit
    attributes.update(variable.extra)
    if variable.start is not None:
        attributes["start"] = " ".join(variable.start)
    node = SubElement(parent, variable.type, attributes)
    for size in variable.shape:
        SubElement(node, "Dimension", {"start": str(size)})


def table(found: list[Variable]) -> str:
    """The FMI 3.0 loader's variable table (``resources/obsfmu_fmi3.txt``)."""
    lines = ["# obsfmu: FMI 3.0 value reference -> the slave's value references (fmus/fmi3/description.py)",
             "# <vr> <F Float64|I Int32> <t time|p parameter|i input|o output> <name> <count> <scalar vrs>"]
    for v in found:
        lines.append(" ".join([str(v.value_reference), _TABLE_TYPE[v.type], _TABLE_CAUSALITY[v.causality], v.name,
                               str(len(v.scalars)), *map(str, v.scalars)]))
    return "\n".join(lines) + "\n"


def read_table(text: str) -> dict[str, list[int]]:
    """FMI 3.0 variable name -> the slave's value references, from :func:`table`'s text."""
    scalars = {}
    for line in text.splitlines():
        if line and not line.startswith("#"):
            _, _, _, name, _, *references = line.split()
            scalars[name] = [int(r) for r in references]
    return scalars


def describe(definition: FmuDefinition, fmi2_description: bytes) -> tuple[bytes, str]:
    """``modelDescription.xml`` (FMI 3.0) and the loader's table of the FMU of ``definition``.

    ``fmi2_description`` is the slave's FMI 2.0 description (same GUID: the FMI 3.0
    ``instantiationToken``); its model attributes, units, log categories and default experiment
    carry over.
    """
    fmi2 = fromstring(fmi2_description)
    found = variables(definition, fmi2_description)
    inputs = [v for v in found if v.causality == "input"]
    outputs = [v for v in found if v.causality == "output"]
    root = Element("fmiModelDescription", {"fmiVersion": "3.0", "modelName": fmi2.get("modelName"),
                                           "instantiationToken": fmi2.get("guid")})
    for key in ("description", "author", "version", "copyright", "license", "generationDateAndTime"):
        if fmi2.get(key):
            root.set(key, fmi2.get(key))
    root.set("generationTool", f"obsfmu (fmus/fmi3) on {fmi2.get('generationTool')}")
    cosimulation = SubElement(root, "CoSimulation", {"modelIdentifier": definition.model_name, **CAPABILITIES})
    cosimulation.set("canHandleVariableCommunicationStepSize", str(definition.variable_step).lower())
    if inputs:  # inputs at t + h through the intermediate update (docs/fmi3.md)
        cosimulation.set("providesIntermediateUpdate", "true")
        cosimulation.set("recommendedIntermediateInputSmoothness", "0")
    units = sorted({unit for v in found for unit in [_unit_and_description(v)[0]] if unit})
    if units:
        definitions = SubElement(root, "UnitDefinitions")
        for unit in units:
            SubElement(definitions, "Unit", {"name": unit})
    categories = fmi2.find("LogCategories")
    if categories is not None:
        node = SubElement(root, "LogCategories")
        for category in categories:
            SubElement(node, "Category", {"name": category.get("name"),
                                          "description": (category.get("description") or "").replace("fmi2", "fmi3")})
    experiment = fmi2.find("DefaultExperiment")
    if experiment is not None:
        SubElement(root, "DefaultExperiment", {k: v for k, v in experiment.attrib.items()
                                               if k in ("startTime", "stopTime", "tolerance", "stepSize")})
    model_variables = SubElement(root, "ModelVariables")
    for variable in found:
        _variable_element(model_variables, variable, intermediate=bool(inputs))
    structure = SubElement(root, "ModelStructure")
    dependencies = " ".join(str(v.value_reference) for v in inputs) if definition.feedthrough else ""
    for v in outputs:
        SubElement(structure, "Output", {"valueReference": str(v.value_reference), "dependencies": dependencies})
    for v in outputs:
        SubElement(structure, "InitialUnknown", {"valueReference": str(v.value_reference)})
    text = parseString(tostring(root, "UTF-8")).toprettyxml(encoding="UTF-8")
    return text, table(found)

