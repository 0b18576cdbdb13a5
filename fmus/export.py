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

The configuration survives importers that ignore the parameter bindings (FMU
Manipulation Toolbox's ``fmucontainer`` does): every exported FMU is a copy
whose ``modelDescription.xml`` declares the system's start values and whose
binary sets them itself at instantiation and reset (``resources/obsfmu_start.txt``,
``fmus/native/loader_common.h``); instances of one model with different start
values get one copy each.  The SSD also declares the system's outputs: one
system connector ``<instance>_<variable>`` per output of every component (``plant_y``,
``observer_theta_hat_1`` for ``observer.theta_hat[1]``) and
(``system_outputs=True``, the default) a connection to it, so a container built
from it exposes every output.  libcosim and ECOS reject connections to the
system's own connectors (SSP 1.0 allows them: no ``endElement``): export for
them with ``system_outputs=False`` (``--no-system-outputs``).

Names OMSimulator accepts: the SSD's model, system and system connectors are identifiers
``[A-Za-z_][A-Za-z0-9_]*`` (the model and system of ``ltv-ls-bounded`` are ``ltv_ls_bounded``, the
scenario's name is the SSD's ``description``); a dotted system connector ``source.y`` made OMSimulator
read the connection ``source.y -> source.y`` as one connector to itself ("Causality mismatch").
Component connectors are the FMUs' own variable names.

FMI 3.0 FMUs (``fmi_version=3``) export as SSP only: SSP 1.0 connects and binds
scalars, so connections join whole FMI 3.0 variables and the bindings hold the
scalar parameters; array start values live in the FMU copies.  OSP system
structures name FMI 2.0 scalar variables (libcosim imports FMI 1.0/2.0).
"""

from __future__ import annotations

import math
import re
import zipfile
from pathlib import Path
from xml.dom import minidom
from xml.etree.ElementTree import Element, SubElement, fromstring, tostring

from fmpy import read_model_description

from .builder import platforms_of
from .fmi3 import TABLE
from .fmi3.description import read_table
from .fmi3.elements import elements
from .master import COUPLINGS, SimulationError
from .native import STARTS
from .runtime.definition import valid_identifier
from .scenarios import Scenario, ensure_fmus, system

__all__ = ["FORMATS", "export", "identifier"]

FORMATS = ("osp", "ssp")
#: name of every component's inline parameter set (some importers, e.g. ecos, apply a named set only)
PARAMETER_SET = "start"
OSP_NS = "http://opensimulationplatform.com/MSMI/OSPSystemStructure"
SSD_NS = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSC_NS = "http://ssp-standard.org/SSP1/SystemStructureCommon"
#: OMSimulator's namespace of its own SSP annotations
OMS_NS = "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd"
SSV_NS = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"


def _pretty(root: Element) -> bytes:
    return minidom.parseString(tostring(root, encoding="utf-8")).toprettyxml(indent="  ", encoding="utf-8")


class _Exported:
    """The scenario's system resolved to element-wise connections and typed start values.

    Names are FMI 2.0 element names (``x0[1]``) for both FMI versions (:mod:`fmus.fmi3.elements`);
    the FMI version is the FMUs' own (their modelDescription).
    """

    def __init__(self, scenario: Scenario, fmus: dict[str, Path], overrides, coupling: str):
        self.system = system(scenario, fmus, overrides)
        descriptions = {c.name: read_model_description(str(c.fmu)) for c in self.system.components}
        versions = {int(md.fmiVersion.split(".")[0]) for md in descriptions.values()}
        if len(versions) != 1:
            raise SimulationError(f"{scenario.name}: its FMUs must share one FMI version, got {sorted(versions)}")
        self.fmi_version = versions.pop()
        self.variables = {name: elements(md) if self.fmi_version == 3 else {v.name: v for v in md.modelVariables}
                          for name, md in descriptions.items()}
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

    def bindings(self, instance: str):
        """The start values SSP 1.0 can bind: all (FMI 2.0), those of scalar variables (FMI 3.0)."""
        variables = self.variables[instance]
        return [item for item in self.typed_start(instance)
                if self.fmi_version == 2 or variables[item[0]].size == 1]

    def fmu_connections(self):
        """Connections in the FMUs' own names: elements (FMI 2.0), whole variables (FMI 3.0)."""
        if self.fmi_version == 2:
            return self.connections
        whole = []
        for (src, out), (dst, inp) in self.connections:
            source, target = self.variables[src][out], self.variables[dst][inp]
            if source.index != target.index or source.size != target.size:
                raise SimulationError(f"{src}.{out} -> {dst}.{inp}: SSP 1.0 connects whole variables; this joins "
                                      f"elements of the FMI 3.0 arrays {src}.{source.variable} and "
                                      f"{dst}.{target.variable}: export FMI 2.0 FMUs for this system")
            pair = ((src, source.variable), (dst, target.variable))
            if pair not in whole:
                whole.append(pair)
        return whole

    def ports(self, instance: str) -> list[tuple[str, str, str]]:
        """(name in the FMU, type, causality) of every input and output (whole variables for FMI 3.0)."""
        found = {}
        for name, variable in self.variables[instance].items():
            if variable.causality in ("input", "output"):
                key = name if self.fmi_version == 2 else variable.variable
                found.setdefault(key, (key, variable.type, variable.causality))
        return list(found.values())

    def copies(self) -> dict[str, tuple[Path, str]]:
        """instance -> (its FMU, the name of its configured copy): one copy per model and start values."""
        names, seen = {}, {}
        for component in self.system.components:
            fmu = Path(component.fmu)
            key = (fmu, tuple(self.typed_start(component.name)))
            taken = [k for k in seen if k[0] == fmu and k != key]
            seen.setdefault(key, fmu.name if not taken else f"{fmu.stem}_{component.name}.fmu")
            names[component.name] = (fmu, seen[key])
        return names

    def write_copy(self, instance: str, target: Path) -> None:
        """The FMU of ``instance`` with its start values as the copy's own (modelDescription + loader)."""
        fmu, _ = self.copies()[instance]
        values = list(self.typed_start(instance))
        with zipfile.ZipFile(fmu) as source, zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as copy:
            table = source.read(f"resources/{TABLE}").decode() if self.fmi_version == 3 else ""
            for item in source.infolist():
                data = source.read(item)
                if item.filename == "modelDescription.xml" and values:
                    data = self._described(instance, data, values)
                copy.writestr(zipfile.ZipInfo(item.filename, item.date_time), data, zipfile.ZIP_DEFLATED)
            if values:
                copy.writestr(f"resources/{STARTS}", self._starts(instance, values, table))

    def _described(self, instance: str, description: bytes, values) -> bytes:
        root = fromstring(description)
        if self.fmi_version == 2:
            by_name = {v.get("name"): v for v in root.iter("ScalarVariable")}
            for name, kind, text in values:
                by_name[name].find(kind).set("start", text)
        else:
            by_name = {v.get("name"): v for v in root.find("ModelVariables")}
            for name, _, text in values:
                element = self.variables[instance][name]
                starts = by_name[element.variable].get("start").split()
                starts[element.index] = text
                by_name[element.variable].set("start", " ".join(starts))
        return b'<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(root, encoding="utf-8")

    def _starts(self, instance: str, values, table: str) -> str:
        """``resources/obsfmu_start.txt``: the slave's value reference of each start value."""
        lines = ["# obsfmu export: start values the binary sets at instantiation and reset (loader_common.h)"]
        scalars = read_table(table)
        for name, kind, text in values:
            variable = self.variables[instance][name]
            reference = (variable.valueReference if self.fmi_version == 2
                         else scalars[variable.variable][variable.index])
            lines.append(f"{'I' if kind == 'Integer' else 'R'} {reference} {text}")
        return "\n".join(lines) + "\n"


def _osp(exported: _Exported, scenario: Scenario, out_dir: Path, step: float) -> Path:
    if exported.fmi_version != 2:
        raise SimulationError("format 'osp': OSP system structures name FMI 2.0 scalar variables (libcosim imports "
                              "FMI 1.0/2.0 FMUs); export FMI 3.0 FMUs as 'ssp'")
    root = Element("OspSystemStructure", {"xmlns": OSP_NS, "version": "0.1"})
    SubElement(root, "StartTime").text = "0.0"
    SubElement(root, "BaseStepSize").text = repr(step)
    SubElement(root, "Algorithm").text = "fixedStep"
    simulators = SubElement(root, "Simulators")
    copies = exported.copies()
    for component in exported.system.components:
        copy = copies[component.name][1]
        exported.write_copy(component.name, out_dir / copy)
        simulator = SubElement(simulators, "Simulator", {"name": component.name, "source": copy})
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


def identifier(text: str) -> str:
    """``text`` as an SSP/OMSimulator identifier: ``ltv-ls-bounded`` -> ``ltv_ls_bounded``,
    ``observer.theta_hat[1]`` -> ``observer_theta_hat_1``, ``A[1,2]`` -> ``A_1_2``."""
    name = re.sub(r"[^A-Za-z0-9_]", "_", text.replace("]", ""))
    return name if valid_identifier(name) else f"_{name}"


def _system_outputs(exported: _Exported) -> list[tuple[str, str, str, str]]:
    """(instance, output, type, the system connector's name) for every output of every component."""
    outputs = [(c.name, name, kind, identifier(f"{c.name}.{name}")) for c in exported.system.components
               for name, kind, causality in exported.ports(c.name) if causality == "output"]
    seen = {}
    for instance, name, _, connector in outputs:
        other = seen.setdefault(connector, f"{instance}.{name}")
        if other != f"{instance}.{name}":
            raise SimulationError(f"the system outputs {other} and {instance}.{name} would both be the connector "
                                  f"{connector!r}: rename one of the variables")
    return outputs


def _ssd(exported: _Exported, scenario: Scenario, step: float, stop_time: float, system_outputs: bool) -> bytes:
    for component in exported.system.components:
        if not valid_identifier(component.name):
            raise SimulationError(f"instance {component.name!r}: SSP importers (OMSimulator) need an identifier "
                                  "[A-Za-z_][A-Za-z0-9_]*")
    name = identifier(scenario.name)
    root = Element("ssd:SystemStructureDescription", {
        "xmlns:ssd": SSD_NS, "xmlns:ssc": SSC_NS, "xmlns:ssv": SSV_NS, "version": "1.0", "name": name,
        "description": f"obsfmu scenario {scenario.name}", "generationTool": "obsfmu"})
    system_node = SubElement(root, "ssd:System", {"name": name, "description": scenario.description})
    wiring = exported.fmu_connections()
    connected = {end for pair in wiring for end in pair}
    outputs = _system_outputs(exported)
    system_connectors = SubElement(system_node, "ssd:Connectors")  # the system's outputs: every component output
    for _, _, kind, connector_name in outputs:
        connector = SubElement(system_connectors, "ssd:Connector", {"name": connector_name, "kind": "output"})
        SubElement(connector, f"ssc:{kind}")
    elements = SubElement(system_node, "ssd:Elements")
    copies = exported.copies()
    for component in exported.system.components:
        node = SubElement(elements, "ssd:Component", {
            "name": component.name, "type": "application/x-fmu-sharedlibrary",
            "source": f"resources/{copies[component.name][1]}"})
        connectors = SubElement(node, "ssd:Connectors")
        for name, kind, causality in exported.ports(component.name):
            if causality == "output" or (component.name, name) in connected:
                connector = SubElement(connectors, "ssd:Connector", {"name": name, "kind": causality})
                SubElement(connector, f"ssc:{kind}")
        values = exported.bindings(component.name)
        if values:
            binding = SubElement(SubElement(node, "ssd:ParameterBindings"), "ssd:ParameterBinding")
            parameter_set = SubElement(SubElement(binding, "ssd:ParameterValues"), "ssv:ParameterSet",
                                       {"version": "1.0", "name": PARAMETER_SET})
            parameters = SubElement(parameter_set, "ssv:Parameters")
            for name, kind, text in values:
                SubElement(SubElement(parameters, "ssv:Parameter", {"name": name}), f"ssv:{kind}", {"value": text})
    connections = SubElement(system_node, "ssd:Connections")
    for (src, out), (dst, inp) in wiring:
        SubElement(connections, "ssd:Connection", {"startElement": src, "startConnector": out,
                                                   "endElement": dst, "endConnector": inp})
    for instance, name, _, connector_name in outputs if system_outputs else ():  # no endElement: the system's own
        SubElement(connections, "ssd:Connection", {"startElement": instance, "startConnector": name,
                                                   "endConnector": connector_name})
    _fixed_step_master(system_node, step)
    SubElement(root, "ssd:DefaultExperiment", {"startTime": "0.0", "stopTime": repr(stop_time)})
    return _pretty(root)


def _fixed_step_master(system_node: Element, step: float) -> None:
    """OMSimulator's annotation of the system's master: a fixed-step co-simulation at ``step``.  Without it
    OMSimulator 3.0 aborts on the package ("[NewSystem] internal error", "basic_string: construction from null is
    not valid"); with it it runs the export and agrees with ``--master jacobi`` (3.5e-12, measured in an audit).
    Other importers ignore a foreign annotation (SSP: ssc:Annotation holds any content)."""
    annotation = SubElement(SubElement(system_node, "ssd:Annotations"), "ssc:Annotation", {"type": "org.openmodelica"})
    information = SubElement(SubElement(annotation, "oms:Annotations", {"xmlns:oms": OMS_NS}),
                             "oms:SimulationInformation")
    SubElement(information, "oms:FixedStepMaster", {"description": "oms-ma", "stepSize": repr(step),
                                                    "absoluteTolerance": "0.0001", "relativeTolerance": "0.0001"})


def export(scenario: Scenario, fmt: str, out_dir: Path | str, build_dir: Path | str = "build", *,
           step: float | None = None, stop_time: float | None = None, overrides=(),
           coupling: str | None = None, fmi_version: int = 2, system_outputs: bool = True,
           standalone: bool = False, platforms=None) -> Path:
    """Write the scenario for another tool; returns the ``.xml`` (osp) or ``.ssp`` file.

    ``fmi_version`` 3 exports the scenario's FMI 3.0 FMUs (SSP only).  ``system_outputs=False``
    leaves out the SSD's connections to the system's output connectors (for libcosim and ECOS).
    ``standalone``: the FMUs carry their Python (:mod:`fmus.standalone`).  ``platforms``: what the FMUs have
    binaries for (default: this machine's; ``"linux64,win64"``): they are built in ``build_dir/<platforms>``,
    so that the build folder's FMUs for this machine stay as they are.
    """
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
    platforms = platforms_of(platforms)
    if platforms != platforms_of(None):
        build_dir = Path(build_dir) / "+".join(platforms)
    fmus = ensure_fmus(scenario, Path(build_dir), fmi_version=fmi_version, standalone=standalone, platforms=platforms)
    exported = _Exported(scenario, fmus, overrides, coupling or scenario.coupling)
    if fmt == "osp":
        return _osp(exported, scenario, out_dir, step)
    path = out_dir / f"{scenario.name}.ssp"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as package:
        package.writestr("SystemStructure.ssd", _ssd(exported, scenario, step, stop_time, system_outputs))
        written = set()
        for instance, (_, copy) in exported.copies().items():
            if copy not in written:
                written.add(copy)
                exported.write_copy(instance, out_dir / f".{copy}.partial")
                package.write(out_dir / f".{copy}.partial", f"resources/{copy}")
                (out_dir / f".{copy}.partial").unlink()
    return path
