"""The suite's non-Python FMI importer (``importer.c``): compile it, write its scripts, run it, read it.

Used by the tests in this folder and by ``benchmarks/native_loader.py``.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import quote

import numpy as np
from fmpy import extract, read_model_description

from obsfmu.fmus.native import fmi_headers

SOURCE = Path(__file__).with_name("importer.c")
#: what an FMU logs at OK level (logging on) when an instance first steps in its compiled kernel (issue 39)
KERNEL_NOTE = "steps run in the compiled kernel"


def compile_importer(directory: Path) -> Path:
    """``importer.c`` compiled with the C compiler into ``directory`` (linked without libpython)."""
    compiler = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    assert compiler, "the native tests need a C compiler (cc)"
    binary = Path(directory) / "importer"
    subprocess.run([compiler, "-O2", "-Wall", "-Werror", f"-I{fmi_headers()}", "-o", str(binary), str(SOURCE),
                    "-ldl", "-lm", "-pthread"], check=True, capture_output=True, text=True)
    return binary


def run(binary: Path, lines: list[str], workdir: Path, env: dict | None = None,
        timeout: float = 600) -> subprocess.CompletedProcess:
    """Run the importer on a script; ``env`` defaults to an empty environment (``env -i``)."""
    script = Path(workdir) / f"script{len(list(Path(workdir).glob('script*')))}.txt"
    script.write_text("\n".join(lines) + "\n")
    return subprocess.run([str(binary), str(script)], env={} if env is None else env, cwd=workdir,
                          capture_output=True, text=True, timeout=timeout)


@dataclass
class Unzipped:
    """An FMU extracted for the importer, with its model description."""

    instance: str
    directory: str
    description: object
    variables: dict = field(init=False)

    def __post_init__(self):
        self.variables = {v.name: v for v in self.description.modelVariables}

    @classmethod
    def of(cls, instance: str, fmu: Path, root: Path) -> "Unzipped":
        return cls(instance, str(extract(str(fmu), unzipdir=str(Path(root) / instance))),
                   read_model_description(str(fmu)))

    @property
    def fmi3(self) -> bool:
        return self.description.fmiVersion.startswith("3")

    @property
    def elements(self) -> dict:
        """FMI 2.0 element names -> FMI 3.0 elements (fmus/fmi3/elements.py); {} for an FMI 2.0 FMU."""
        from obsfmu.fmus.fmi3.elements import elements
        return elements(self.description) if self.fmi3 else {}

    @property
    def outputs(self) -> list[str]:
        if self.fmi3:
            return [name for name, e in self.elements.items() if e.causality == "output"]
        return [v.name for v in self.description.modelVariables if v.causality == "output"]

    def vr(self, name: str) -> int:
        return self.variables[name].valueReference

    def port(self, name: str) -> list[str]:
        names = self.elements or self.variables
        return [name] if name in names else [n for n in names if n.startswith(name + "[")]

    def declaration(self, host_path=str) -> str:
        """The importer's ``fmu``/``fmu3`` line; ``host_path`` turns the folder into the importer's path (wine: a
        drive letter), which goes percent-encoded (it may hold spaces)."""
        identifier = self.description.coSimulation.modelIdentifier
        directory = quote(host_path(self.directory), safe="/:\\")
        if self.fmi3:
            return f"fmu3 {self.instance} {directory} {identifier} {self.description.instantiationToken}"
        return f"fmu {self.instance} {directory} {identifier} {self.description.guid}"

    def variables3(self, causality: str) -> list:
        return [v for v in self.description.modelVariables if v.causality == causality]


def system_script(unzipped: list[Unzipped], connections, starts: dict[str, dict[str, float]],
                  host_path=str) -> list[str]:
    """The importer's declarations of a system: like :func:`fmus.master.wiring.wire`, element by element."""
    lines, offsets, offset = [], {}, 0
    by_name = {u.instance: u for u in unzipped}
    for u in unzipped:
        lines.append(u.declaration(host_path))
        offsets[u.instance] = offset
        offset += len(u.outputs)
        if u.fmi3:  # whole variables: outputs in their order, every input variable
            elements = u.elements
            lines += [f"output3 {u.instance} {v.valueReference} {sum(e.variable == v.name for e in elements.values())}"
                      for v in u.variables3("output")]
            lines += [f"array3 {u.instance} {v.valueReference} {sum(e.variable == v.name for e in elements.values())}"
                      for v in u.variables3("input")]
        else:
            lines += [f"output {u.instance} {u.vr(name)}" for name in u.outputs]
        if any(o.dependencies for o in u.description.outputs):
            lines.append(f"feedthrough {u.instance}")
        for name, value in starts.get(u.instance, {}).items():
            if u.fmi3:
                e = u.elements[name]
                kind = "integer" if e.type == "Integer" else "real"
                lines.append(f"start3 {u.instance} {kind} {e.valueReference} {e.size} {e.index} {value!r}")
                continue
            kind = "integer" if u.variables[name].type in ("Integer", "Enumeration") else "real"
            lines.append(f"start {u.instance} {kind} {u.vr(name)} {value!r}")
    for connection in connections:
        (src, src_var), (dst, dst_var) = (connection.source.split(".", 1), connection.target.split(".", 1))
        for out_name, in_name in zip(by_name[src].port(src_var), by_name[dst].port(dst_var), strict=True):
            source = offsets[src] + by_name[src].outputs.index(out_name)
            target = by_name[dst]
            if target.fmi3:
                e = target.elements[in_name]
                lines.append(f"input3 {dst} {e.valueReference} {e.index} {source}")
            else:
                lines.append(f"input {dst} {target.vr(in_name)} {source}")
    return lines


def read_csv(path: Path) -> np.ndarray:
    return np.loadtxt(path, delimiter=",", ndmin=2)


def parse_calls(stdout: str) -> dict[str, list[tuple[str, int, float, list[str]]]]:
    """``case id -> [(call, status, value, log messages of that call), ...]`` from ``calls`` output;
    each message is ``"<level> <text>"`` (the fmi2Status it was logged with, e.g. ``"3 fmi2DoStep is ..."``)."""
    cases: dict[str, list] = {}
    logs: list[str] = []
    for line in stdout.splitlines():
        if line.startswith("log "):
            logs.append(line.split(" ", 2)[2])
        elif line.startswith("call "):
            _, case, name, status, *value = line.split(" ")
            if name == "instantiate:badguid":
                cases.setdefault(case, []).append((name, 0 if status == "ok" else -1, float("nan"), logs))
            else:
                cases.setdefault(case, []).append((name, int(status), float(value[0]), logs))
            logs = []
        elif line.startswith("case "):
            logs = []
    return cases


def scenario_script(scenario, fmus: dict, root: Path, csv: Path, stop: float, step: float,
                    host_path=str) -> list[str]:
    """The importer's script of one Jacobi run of ``scenario`` with the FMUs ``fmus`` (model -> .fmu, FMI 2.0
    or 3.0), unzipped under ``root``, written to ``csv``, then ``clear``; ``host_path`` turns a path of this
    machine into the importer's (wine: ``Z:/...``)."""
    unzipped = [Unzipped.of(instance, fmus[model], Path(root) / instance) for instance, model, _ in scenario.components]
    starts = {instance: start for instance, _, start in scenario.components}
    return system_script(unzipped, scenario.connections, starts, host_path) + [
        f"cosim jacobi {scenario.coupling} 0 {stop!r} {step!r} {quote(host_path(str(csv)), safe='/:')}", "clear"]

