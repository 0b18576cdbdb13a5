"""Export a scenario as a system description for other co-simulation tools.

* ``osp`` -- an Open Simulation Platform ``OspSystemStructure.xml`` next to
  copies of the FMUs (run it with libcosim / libcosimpy / ``cosim run``).
* ``ssp`` -- an SSP 1.0 package ``<scenario>.ssp``: a zip with
  ``SystemStructure.ssd`` and the FMUs under ``resources/``; start values are
  inline parameter bindings.

Both contain the instances, connections (element-wise), start values and the
communication step.  Those tools step every FMU in parallel (like our Jacobi
master) and hold inputs between communication points; with
``coupling="linear"`` the export sets every connected input's
``<port>_interpolation`` to 1 (extrapolate from the previous point), which
makes the FMUs do inside what our master does with input derivatives.
"""

from __future__ import annotations

import math
import shutil
import zipfile
from pathlib import Path
from xml.dom import minidom
from xml.etree.ElementTree import Element, SubElement, tostring

from fmpy import read_model_description

from .master import COUPLINGS, SimulationError
from .scenarios import Scenario, ensure_fmus, system

__all__ = ["FORMATS", "export"]

FORMATS = ("osp", "ssp")
#: name of every component's inline parameter set (some importers, e.g. ecos, apply a named set only)
PARAMETER_SET = "start"
OSP_NS = "http://opensimulationplatform.com/MSMI/OSPSystemStructure"
SSD_NS = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSC_NS = "http://ssp-standard.org/SSP1/SystemStructureCommon"
SSV_NS = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"


def _pretty(root: Element) -> bytes:
    return minidom.parseString(tostring(root, encoding="utf-8")).toprettyxml(indent="  ", encoding="utf-8")


class _Exported:
    """The scenario's system resolved to element-wise connections and typed start values."""

    def __init__(self, scenario: Scenario, build_dir: Path, overrides, coupling: str):
        fmus = ensure_fmus(scenario, build_dir)
        self.system = system(scenario, fmus, overrides)
        self.variables = {c.name: {v.name: v for v in read_model_description(str(c.fmu)).modelVariables}
                          for c in self.system.components}
        self.connections = [pair for connection in self.system.connections for pair in self._elements(connection)]
        self.start = {c.name: dict(c.start) for c in self.system.components}
        if coupling == "linear":
            for _, (instance, variable) in self.connections:
                mode = f"{variable.split('[')[0]}_interpolation"
                if mode in self.variables[instance]:
                    self.start[instance].setdefault(mode, 1)
        for instance, values in self.start.items():
            for name in values:
                if name not in self.variables[instance]:
                    raise SimulationError(f"{instance}.{name}: no such variable")

    def _port(self, instance: str, name: str) -> list[str]:
        variables = self.variables[instance]
        return [name] if name in variables else [n for n in variables if n.startswith(name + "[")]

    def _elements(self, connection):
        (src, src_var), (dst, dst_var) = (p.split(".", 1) for p in (connection.source, connection.target))
        outputs, inputs = self._port(src, src_var), self._port(dst, dst_var)
        if not outputs or len(outputs) != len(inputs):
            raise SimulationError(f"connection {connection.source} -> {connection.target} cannot be resolved")
        return [((src, o), (dst, i)) for o, i in zip(outputs, inputs)]

    def typed_start(self, instance: str):
        for name, value in self.start[instance].items():
            kind = self.variables[instance][name].type
            yield name, kind, (str(int(value)) if kind == "Integer" else repr(float(value)))


def _osp(exported: _Exported, scenario: Scenario, out_dir: Path, step: float) -> Path:
    root = Element("OspSystemStructure", {"xmlns": OSP_NS, "version": "0.1"})
    SubElement(root, "StartTime").text = "0.0"
    SubElement(root, "BaseStepSize").text = repr(step)
    SubElement(root, "Algorithm").text = "fixedStep"
    simulators = SubElement(root, "Simulators")
    for component in exported.system.components:
        shutil.copy2(component.fmu, out_dir / Path(component.fmu).name)
        simulator = SubElement(simulators, "Simulator", {"name": component.name, "source": Path(component.fmu).name})
        values = list(exported.typed_start(component.name))
        if values:
            initial = SubElement(simulator, "InitialValues")
            for name, kind, text in values:
                SubElement(SubElement(initial, "InitialValue", {"variable": name}), kind, {"value": text})
    connections = SubElement(root, "Connections")
    for (src, out), (dst, inp) in exported.connections:
        pair = SubElement(connections, "VariableConnection")
        SubElement(pair, "Variable", {"simulator": src, "name": out})
        SubElement(pair, "Variable", {"simulator": dst, "name": inp})
    path = out_dir / "OspSystemStructure.xml"
    path.write_bytes(_pretty(root))
    return path


def _ssd(exported: _Exported, scenario: Scenario, step: float, stop_time: float) -> bytes:
    root = Element("ssd:SystemStructureDescription", {
        "xmlns:ssd": SSD_NS, "xmlns:ssc": SSC_NS, "xmlns:ssv": SSV_NS,
        "version": "1.0", "name": scenario.name, "generationTool": "obsfmu"})
    system_node = SubElement(root, "ssd:System", {"name": scenario.name, "description": scenario.description})
    connected = {end for pair in exported.connections for end in pair}
    elements = SubElement(system_node, "ssd:Elements")
    for component in exported.system.components:
        node = SubElement(elements, "ssd:Component", {
            "name": component.name, "type": "application/x-fmu-sharedlibrary",
            "source": f"resources/{Path(component.fmu).name}"})
        connectors = SubElement(node, "ssd:Connectors")
        for name, variable in exported.variables[component.name].items():
            if variable.causality in ("input", "output") and (component.name, name) in connected:
                connector = SubElement(connectors, "ssd:Connector", {"name": name, "kind": variable.causality})
                SubElement(connector, f"ssc:{variable.type}")
        values = list(exported.typed_start(component.name))
        if values:
            binding = SubElement(SubElement(node, "ssd:ParameterBindings"), "ssd:ParameterBinding")
            parameter_set = SubElement(SubElement(binding, "ssd:ParameterValues"), "ssv:ParameterSet",
                                       {"version": "1.0", "name": PARAMETER_SET})
            parameters = SubElement(parameter_set, "ssv:Parameters")
            for name, kind, text in values:
                SubElement(SubElement(parameters, "ssv:Parameter", {"name": name}), f"ssv:{kind}", {"value": text})
    connections = SubElement(system_node, "ssd:Connections")
    for (src, out), (dst, inp) in exported.connections:
        SubElement(connections, "ssd:Connection", {"startElement": src, "startConnector": out,
                                                   "endElement": dst, "endConnector": inp})
    SubElement(root, "ssd:DefaultExperiment", {"startTime": "0.0", "stopTime": repr(stop_time)})
    return _pretty(root)


def export(scenario: Scenario, fmt: str, out_dir: Path | str, build_dir: Path | str = "build", *,
           step: float | None = None, stop_time: float | None = None, overrides=(),
           coupling: str | None = None) -> Path:
    """Write the scenario for another tool; returns the ``.xml`` (osp) or ``.ssp`` file."""
    if fmt not in FORMATS:
        raise SimulationError(f"format: {fmt!r} is not one of {FORMATS}")
    step = scenario.step if step is None else step
    stop_time = scenario.stop_time if stop_time is None else stop_time
    for name, value in (("step", step), ("stop_time", stop_time)):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise SimulationError(f"{name}: must be a positive finite number, got {value!r}")
    if coupling is not None and coupling not in COUPLINGS:
        raise SimulationError(f"coupling: {coupling!r} is not one of {COUPLINGS}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    exported = _Exported(scenario, Path(build_dir), overrides, coupling or scenario.coupling)
    if fmt == "osp":
        return _osp(exported, scenario, out_dir, step)
    path = out_dir / f"{scenario.name}.ssp"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as package:
        package.writestr("SystemStructure.ssd", _ssd(exported, scenario, step, stop_time))
        for component in exported.system.components:
            package.write(component.fmu, f"resources/{Path(component.fmu).name}")
    return path
