"""The suite's non-Python FMI importer (``importer.c``): compile it, write its scripts, run it, read it.

Used by the tests in this folder and by ``benchmarks/native_loader.py``.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description

from fmus.native import fmi_headers

SOURCE = Path(__file__).with_name("importer.c")


def compile_importer(directory: Path) -> Path:
    """``importer.c`` compiled with the C compiler into ``directory`` (linked without libpython)."""
    compiler = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    assert compiler, "the native tests need a C compiler (cc)"
    binary = Path(directory) / "importer"
    subprocess.run([compiler, "-O2", "-Wall", "-Werror", f"-I{fmi_headers()}", "-o", str(binary), str(SOURCE),
                    "-ldl", "-lm"], check=True, capture_output=True, text=True)
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
    def outputs(self) -> list[str]:
        return [v.name for v in self.description.modelVariables if v.causality == "output"]

    def vr(self, name: str) -> int:
        return self.variables[name].valueReference

    def port(self, name: str) -> list[str]:
        return [name] if name in self.variables else [n for n in self.variables if n.startswith(name + "[")]

    def declaration(self) -> str:
        identifier = self.description.coSimulation.modelIdentifier
        return f"fmu {self.instance} {self.directory} {identifier} {self.description.guid}"


def system_script(unzipped: list[Unzipped], connections, starts: dict[str, dict[str, float]]) -> list[str]:
    """The importer's declarations of a system: like :func:`fmus.master._wire`, element by element."""
    lines, offsets, offset = [], {}, 0
    by_name = {u.instance: u for u in unzipped}
    for u in unzipped:
        lines.append(u.declaration())
        offsets[u.instance] = offset
        offset += len(u.outputs)
        lines += [f"output {u.instance} {u.vr(name)}" for name in u.outputs]
        if any(o.dependencies for o in u.description.outputs):
            lines.append(f"feedthrough {u.instance}")
        for name, value in starts.get(u.instance, {}).items():
            kind = "integer" if u.variables[name].type in ("Integer", "Enumeration") else "real"
            lines.append(f"start {u.instance} {kind} {u.vr(name)} {value!r}")
    for connection in connections:
        (src, src_var), (dst, dst_var) = (connection.source.split(".", 1), connection.target.split(".", 1))
        for out_name, in_name in zip(by_name[src].port(src_var), by_name[dst].port(dst_var), strict=True):
            source = offsets[src] + by_name[src].outputs.index(out_name)
            lines.append(f"input {dst} {by_name[dst].vr(in_name)} {source}")
    return lines


def read_csv(path: Path) -> np.ndarray:
    return np.loadtxt(path, delimiter=",", ndmin=2)


def parse_calls(stdout: str) -> dict[str, list[tuple[str, int, float, list[str]]]]:
    """``case id -> [(call, status, value, log messages of that call), ...]`` from ``calls`` output."""
    cases: dict[str, list] = {}
    logs: list[str] = []
    for line in stdout.splitlines():
        if line.startswith("log "):
            logs.append(line.split(" ", 3)[3])
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
