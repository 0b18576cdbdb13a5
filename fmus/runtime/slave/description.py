"""The FMU's modelDescription.xml: pythonfmu's, with the real capabilities, units, mode ranges and model structure."""

from __future__ import annotations

from xml.etree.ElementTree import Element, SubElement

from pythonfmu import Fmi2Causality

__all__ = ["CAPABILITIES", "ModelDescription"]

#: what the native binary (fmus/native) and this class really support
CAPABILITIES = {
    "needsExecutionTool": "true",  # a Python interpreter with numpy and scipy
    "canHandleVariableCommunicationStepSize": "true",
    "canInterpolateInputs": "true",
    "maxOutputDerivativeOrder": "0",
    "canRunAsynchronuously": "false",
    "canBeInstantiatedOnlyOncePerProcess": "false",
    "canNotUseMemoryManagementFunctions": "true",
    "canGetAndSetFMUstate": "true",
    "canSerializeFMUstate": "true",
    "providesDirectionalDerivative": "false",
}


class ModelDescription:
    """The model description of :class:`~fmus.runtime.slave.BlockSlave` (written by the builder, :mod:`fmus.builder`)."""

    def to_xml(self, model_options=None) -> Element:
        """pythonfmu's description plus units, mode ranges and a complete ModelStructure."""
        root = super().to_xml(model_options or {})
        root.find("CoSimulation").attrib.update(CAPABILITIES, canHandleVariableCommunicationStepSize=str(
            self.definition.variable_step).lower(), maxOutputDerivativeOrder=str(int(self.definition.output_derivatives)))
        self._add_units(root)
        for variable in root.iter("ScalarVariable"):
            if variable.get("name", "").endswith("_interpolation"):
                integer = variable.find("Integer")
                integer.set("min", "0")
                integer.set("max", "2")
        self._rebuild_model_structure(root)
        return root

    def _add_units(self, root: Element):
        units = sorted(set(self._units.values()))
        if not units:
            return
        definitions = Element("UnitDefinitions")
        for unit in units:
            SubElement(definitions, "Unit", {"name": unit})
        children = list(root)
        position = [i for i, c in enumerate(children) if c.tag == "CoSimulation"][0] + 1
        root.insert(position, definitions)
        for variable in root.iter("ScalarVariable"):
            unit = self._units.get(variable.get("name"))
            if unit:
                variable.find("Real").set("unit", unit)

    def _rebuild_model_structure(self, root: Element):
        structure = root.find("ModelStructure")
        for child in list(structure):
            structure.remove(child)
        variables = list(self.vars.values())
        index = {v.name: i + 1 for i, v in enumerate(variables)}
        outputs = [v for v in variables if v.causality == Fmi2Causality.output]
        inputs = [v for v in variables if v.causality == Fmi2Causality.input]
        dependencies = " ".join(str(index[v.name]) for v in inputs) if self.definition.feedthrough else ""
        if outputs:
            node = SubElement(structure, "Outputs")
            for v in outputs:
                SubElement(node, "Unknown", {"index": str(index[v.name]), "dependencies": dependencies})
            node = SubElement(structure, "InitialUnknowns")
            for v in outputs:
                SubElement(node, "Unknown", {"index": str(index[v.name])})
