"""What ``obsfmu`` does with ``--config FILE`` (the CLI calls one function of this module each).

``--config`` names a system file (:mod:`fmus.system.load`); the older single-plant design file of
:mod:`fmus.config` (a ``[plant]`` and ``[observer]``, no ``[components]``) is still built by
``obsfmu build --config`` as before.  A system file's scenario is named by the file's resolved path,
which :func:`fmus.scenarios.get` understands in every process (sweep workers included).
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

from obsfmu.observers.checks import ParameterError

__all__ = ["scenario_key", "definitions_of", "build_definitions", "show", "is_design_file", "holds_components",
           "require_rereadable", "configure_show"]


def scenario_key(args) -> str:
    """The scenario a command runs: ``--config FILE`` (its resolved path) or the SCENARIO argument."""
    config, name = getattr(args, "config", None), getattr(args, "scenario", None)
    if config and name:
        raise ParameterError(f"--config {config}: give either a SCENARIO or --config FILE, not both")
    if not config:
        if not name:
            raise ParameterError("SCENARIO: missing; give a scenario (obsfmu list) or --config FILE.toml")
        return name
    from . import scenario_from_file
    path = Path(config)
    scenario_from_file(path)                   # checked whole now: one line naming the field, nothing built
    return str(path.resolve())


def require_rereadable(path: Path | str, command: str) -> None:
    """``--config path`` of a command that reads the file more than once (``sweep``: here and in each
    worker) must be a regular file, not a pipe (``<(obsfmu show ship)``): else one line naming it."""
    import stat
    try:
        mode = Path(path).stat().st_mode
    except OSError:
        return                                   # missing or unreadable: the reader names the reason
    if not stat.S_ISREG(mode) and not stat.S_ISDIR(mode):
        raise ParameterError(f"--config {path}: not a regular file (a pipe?); {command} reads it more than once "
                             "(its workers too): write it to a file first (obsfmu show SCENARIO > my.toml)")


def holds_components(path: Path | str) -> bool:
    """The TOML file ``path`` has ``[components.NAME]`` tables: a system file (not a campaign's file)."""
    import re
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError:
        return False
    return re.search(r"^\s*\[\s*components\s*[.\]]", text, re.MULTILINE) is not None


def is_design_file(path: Path | str) -> bool:
    """The file is the older single-plant design file (``[plant]``, no ``[components]``)."""
    import tomllib
    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False
    return "plant" in data and "components" not in data


def _design_definitions(path: Path) -> tuple[list, list[str]]:
    """The older design file's definitions and the designed gains to print."""
    from ..config import design_from_config, load_config
    from .linear_types import matrix_text, poles_text
    design = design_from_config(load_config(path))
    notes = [f"observer: N = {matrix_text(design.N)}; eig(A - N C) = [{poles_text(design.observer_poles)}]"]
    if design.K is not None:
        notes.append(f"controller: K = {matrix_text(design.K)}; eig(A - B K) = [{poles_text(design.controller_poles)}]")
    return design.definitions(design.experiment()), notes


def definitions_of(path: Path | str) -> list:
    """The FMU definitions of the file ``path``, checked whole (nothing written); the designed gains and
    poles are printed."""
    path = Path(path)
    if is_design_file(path):
        definitions, notes = _design_definitions(path)
    else:
        from . import load_system
        spec = load_system(path)
        definitions, notes = spec.definitions(), spec.notes
    for note in notes:
        print(note)
    return definitions


def build_definitions(definitions: list, out: Path, fmi_version: int = 2, standalone: bool = False,
                      platforms=None) -> list[Path]:
    """Build ``definitions`` into ``out``; an error leaves nothing half-written.

    Parameters
    ----------
    definitions : list of FmuDefinition
        From :func:`definitions_of`.
    out : Path
        The build folder (``out/fmi3`` for FMI 3.0).
    fmi_version : {2, 3}
    standalone : bool
        FMUs that carry their Python runtime (:func:`fmus.builder.build_fmu`).
    platforms : str or sequence of str, optional
        What they have binaries for (default: this machine's; ``"linux64,win64"``).

    Returns
    -------
    list of Path
        The FMUs, built into a temporary folder beside their place and moved there once all are built.
    """
    from ..builder import build_fmu, record_path
    from ..fmi3 import build_folder
    folder = build_folder(out, fmi_version)
    folder.mkdir(parents=True, exist_ok=True)
    temporary = Path(tempfile.mkdtemp(prefix=".obsfmu_build_", dir=folder))
    try:
        built = [build_fmu(definition, temporary, fmi_version=fmi_version, standalone=standalone,
                           platforms=platforms) for definition in definitions]
        paths = []
        for fmu in built:
            target = folder / fmu.name
            fmu.replace(target)
            record_path(fmu).replace(record_path(target))      # its build record goes with it
            paths.append(target)
        return paths
    finally:
        shutil.rmtree(temporary, ignore_errors=True)


def show(args) -> int:
    """``obsfmu show --fields`` (the field reference, markdown), ``obsfmu show SCENARIO`` (the system file
    that defines the scenario, as it is) or ``obsfmu show --config FILE`` (checked: its components, ports,
    connections and designed gains)."""
    from . import field_reference, load_system
    if args.fields:
        sys.stdout.write(field_reference())
        return 0
    if args.scenario:
        sys.stdout.write(_scenario_file(args.scenario).read_text(encoding="utf-8"))
        return 0
    if not args.config:
        raise ParameterError("show: give SCENARIO, --fields or --config FILE.toml")
    spec = load_system(args.config)
    print(f"{spec.name}: {spec.description}")
    for instance, component in spec.components.items():
        for definition in component.definitions:
            inputs = ", ".join(f"{p.name}[{p.size}]" for p in definition.inputs) or "none"
            outputs = ", ".join(f"{p.name}[{p.size}]" for p in definition.outputs)
            print(f"  {instance} ({component.kind}, FMU {definition.model_name}): inputs {inputs}; outputs {outputs}")
            for direction, ports in (("in", definition.inputs), ("out", definition.outputs)):
                for port in ports:
                    print(f"      {direction} {_port_text(instance, port)}")
    for connection in spec.connections:
        print(f"  {connection.source} -> {connection.target}")
    for note in spec.notes:
        print(note)
    return 0


def _port_text(instance: str, port) -> str:
    """``plant.theta[1..8] (unit): description``: a port's columns, units and layout (issue 38)."""
    columns = f"{instance}.{port.name}" if port.size == 1 else f"{instance}.{port.name}[1..{port.size}]"
    unit = port.unit if isinstance(port.unit, str) else (", ".join(map(str, port.unit)) if port.unit else "")
    names = f" = [{', '.join(port.labels)}]" if port.labels else ""
    return f"{columns}{f' ({unit})' if unit else ''}: {port.description}{names}"


def _scenario_file(name: str) -> Path:
    """The system file of the paper scenario ``name``."""
    from .. import scenarios
    scenario = scenarios.get(name)
    if scenario.system_file is None:
        raise ParameterError(f"SCENARIO: {name!r} is not defined by a system file")
    return scenario.system_file


def configure_show(parser) -> None:
    """The options of ``obsfmu show``."""
    parser.add_argument("scenario", nargs="?", metavar="SCENARIO",
                        help="print the system file of a paper scenario (obsfmu list): a working start for "
                        "your own (obsfmu show ship > my.toml)")
    parser.add_argument("--fields", action="store_true",
                        help="print the system file's field reference (markdown, docs/system-file-reference.md)")
    parser.add_argument("--config", metavar="FILE.toml", help="check a system file and print its components, "
                        "ports, connections and designed gains")
