"""Reading a system file: TOML -> a checked :class:`~fmus.system.model.SystemSpec`.

Every mistake is one :class:`~observers.checks.ParameterError` line naming the file, the line and the
field (``dcmotor.toml:12: components.plant.A: row 2 has 1 entry, row 1 has 2``); unknown fields get a
did-you-mean.  The file is refused at once beyond :data:`MAX_FILE_BYTES`, with a control character, or
with more than :data:`MAX_COMPONENTS` components.  Reading builds nothing: the FMU definitions are
made (and so checked) in memory, the FMUs only later from them.
"""

from __future__ import annotations

import difflib
import re
import sys
import unicodedata
from pathlib import Path

from obsfmu.observers.checks import ParameterError
from obsfmu.observers.expressions import Names, Source, compile_expression

from ..master import COUPLINGS, ORDERS
from ..runtime.definition import Parameter
from .connect import check_compares, check_connections, check_plotted, check_values, require_connected
from .locate import Locator
from .model import ComponentSpec, SystemSpec
from .kinds import component_type
from .schema import TYPES, Context, Field
from .values import check_text, check_value

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["load_system", "parse_system", "TOP_FIELDS", "EXPERIMENT_FIELDS", "COMPARE_FIELDS", "MAX_FILE_BYTES",
           "MAX_COMPONENTS"]

MAX_FILE_BYTES = 4 * 2 ** 20   #: a system file (a table source of 100 000 break points fits)
MAX_COMPONENTS = 200
_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,63}")

TOP_FIELDS = (
    Field("name", "string", "identifier; the FMUs are called <name>_<component>", example='"dcmotor"'),
    Field("description", "string", "one line on what the system is", "", example='"DC motor with observer"'),
    Field("time_unit", "choice", "unit of time of the models", "s", choices=("s", "min", "h", "d")),
    Field("connections", "connections", 'list of "a.y -> b.u" (whole ports, or elements a.y[2])', None,
          example='["plant.y -> observer.y"]'),
)
EXPERIMENT_FIELDS = (
    Field("stop_time", "number", "end of the run", unit="(time unit)", example="2.0"),
    Field("step", "number", "communication step", unit="(time unit)", example="1e-3"),
    Field("master", "choice", "stepping order", "gauss-seidel", choices=ORDERS),
    Field("coupling", "choice", "inputs inside a step: interpolated/extrapolated, or held", "linear",
          choices=COUPLINGS),
    Field("output_interval", "number", "spacing of the CSV rows (absent: every communication point; "
          "--output-interval overrides it)", None,
          "(time unit)", "0.01"),
    Field("tolerance", "number", "adaptive master: error per unit step on every output", 1e-6, "", "1e-6"),
    Field("ramp", "integer", "the first step split into step/2^ramp, ..., step/2 (a fast initial transient)", 0,
          example="6", maximum=30),
)
COMPARE_FIELDS = (
    Field("estimate", "string", "an output port: the estimate", example='"observer.x_hat"'),
    Field("truth", "string", "an output port of the same size: the true value", example='"plant.x"'),
    Field("tolerance", "number", "convergence time: from when |truth - estimate| stays below it", 1e-3,
          "(port's unit)", "1e-3"),
)
_SECTIONS = {"experiment", "components", "values", "report", "plot"}


def _did_you_mean(name: str, known) -> str:
    close = difflib.get_close_matches(name, list(known), n=1)
    return f"; did you mean {close[0]!r}?" if close else f"; known: {', '.join(sorted(known))}"


def _unknown(where: str, table: dict, fields) -> None:
    known = [f if isinstance(f, str) else f.name for f in fields]
    for key in table:
        if key == "connections" and where:
            raise ParameterError(f"{where}connections: in TOML a key after a [table] header belongs to that table; "
                                 "write connections = [...] before the first [table] of the file")
        if key not in known:
            check_text(f"{where}{key}", key)
            raise ParameterError(f"{where}{key}: unknown field{_did_you_mean(key, known)}")


def _table(where: str, value) -> dict:
    if not isinstance(value, dict):
        raise ParameterError(f"{where}: expected a table, got {value!r:.60}")
    return value


def _fields(where: str, table: dict, fields) -> tuple[dict, set]:
    """The values of ``fields`` from ``table`` (checked, defaults filled in) and the names given."""
    _unknown(where, table, fields)
    values = {}
    for f in fields:
        if f.name in table:
            values[f.name] = check_value(f, where + f.name, table[f.name])
        elif f.required:
            raise ParameterError(f"{where}{f.name}: missing (required)")
        else:
            values[f.name] = f.default
    return values, set(table)


def _identifier(where: str, value) -> str:
    check_text(where, value)
    if not _IDENTIFIER.fullmatch(value):
        raise ParameterError(f"{where}: {value!r} is not an identifier (a letter or _, then letters, digits, _; "
                             "at most 64)")
    return value


def _expressions_located(spec_values: dict, prefix: str, locator: Locator, path: str) -> None:
    """Compile ``f`` and ``h`` once here so that a refusal names the file, line and column."""
    parameters = spec_values["parameters"] or {}
    names = Names(x=len(spec_values["f"]), u=spec_values["inputs"], p=len(parameters),
                  parameters={name: i for i, name in enumerate(parameters, start=1)})
    for key in ("f", "h"):
        after = 0
        for i, text in enumerate(spec_values[key], start=1):
            place = locator.string(prefix + key, text, after)
            line, column, after = place if place else (locator.line(prefix + key) or 1, 1, after)
            compile_expression(text, names, Source(f"{prefix}{key}[{i}]", path, line, column))


def _component(instance: str, table, others: dict, context: Context, locator: Locator, path: str) -> ComponentSpec:
    prefix = f"components.{instance}."
    table = _table(prefix.rstrip("."), table)
    if "kind" not in table:
        raise ParameterError(f"{prefix}kind: missing; the type of the component (see 'obsfmu show --fields')")
    kind = check_text(prefix + "kind", table["kind"])
    entry = component_type(kind)
    if entry is None:
        raise ParameterError(f"{prefix}kind: unknown component type {kind!r}{_did_you_mean(kind, TYPES)}")
    values, given = _fields(prefix, table, entry.fields)
    for name in entry.depends:
        if values[name] not in others:
            raise ParameterError(f"{prefix}{name}: {values[name]!r} is not a component defined before "
                                 f"{instance!r}{_did_you_mean(values[name], others) if others else ''}")
    if kind == "expression":
        _expressions_located(values, prefix, locator, path)
    context.prefix = prefix
    context.others = {name: (spec.kind, spec.values) for name, spec in others.items()}
    try:
        definitions = entry.define(f"{context.name}_{instance}", {**values, "given": given}, context)
    except ParameterError as exc:       # the kinds name their own arguments: the component's prefix added
        message = str(exc)
        raise ParameterError(message if message.startswith(("components.", path)) else prefix + message) from None
    return ComponentSpec(instance, kind, values, given, definitions)


def _components(data: dict, context: Context, locator: Locator, path: str) -> dict[str, ComponentSpec]:
    table = _table("components", data.get("components", {}))
    if not table:
        raise ParameterError("components: none; a system needs at least one [components.NAME] table")
    if len(table) > MAX_COMPONENTS:
        raise ParameterError(f"components: {len(table)} components, more than the limit of {MAX_COMPONENTS}")
    specs: dict[str, ComponentSpec] = {}
    for instance, entry in table.items():
        _identifier(f"components.{instance}", instance)
        specs[instance] = _component(instance, entry, specs, context, locator, path)
    return specs


def _experiment(data: dict) -> dict:
    if "experiment" not in data:
        raise ParameterError("experiment: missing section [experiment] (stop_time and step are required)")
    values, _ = _fields("experiment.", _table("experiment", data["experiment"]), EXPERIMENT_FIELDS)
    for key in ("stop_time", "step", "output_interval", "tolerance"):
        if values[key] is not None and values[key] <= 0:
            raise ParameterError(f"experiment.{key}: must be > 0, got {values[key]:g}")
    if values["step"] > values["stop_time"]:
        raise ParameterError(f"experiment.step: {values['step']:g} is longer than the stop time "
                             f"{values['stop_time']:g}")
    return values


def _plotted(data: dict, components: dict) -> list[list[str]]:
    """``[plot]``: ``signals``, the outputs drawn beside the comparisons (one panel each)."""
    plot = _table("plot", data.get("plot", {}))
    _unknown("plot.", plot, ("signals",))
    return check_plotted(plot.get("signals", []), components)


def _compares(data: dict) -> list[dict]:
    report = _table("report", data.get("report", {}))
    _unknown("report.", report, ("compare", "reference"))
    items = report.get("compare", [])
    if not isinstance(items, list):
        raise ParameterError("report.compare: expected [[report.compare]] tables")
    compares = [_fields(f"report.compare[{i}].", _table(f"report.compare[{i}]", item), COMPARE_FIELDS)[0]
                for i, item in enumerate(items, start=1)]
    if "reference" in report:
        check_text("report.reference", report["reference"])
    return compares


#: characters that reorder text on screen (Trojan Source, CVE-2021-42574): refused anywhere in a file
BIDI_CONTROLS = frozenset("\u061c\u200e\u200f\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069")
_EXPRESSION = re.compile(r"(\S+?)\[(\d+)\] \(line (\d+), column \d+ of the expression\)")


def _line_of(field: str, locator: Locator) -> int | None:
    """The line a message's field is on: the key, the i-th connection, the component of ``a.u``, or the line of
    an expression (``components.plant.f[2] (line 1, column 8 of the expression)``: its string's line)."""
    expression = _EXPRESSION.fullmatch(field)
    if expression:
        key, index, line = expression[1], int(expression[2]), int(expression[3])
        start = locator.item_line(key, index) or locator.line(key)
        return None if start is None else start + line - 1
    first = field.split(" ")[0]
    index = re.fullmatch(r"connections\[(\d+)\]", first)
    if index:
        return locator.item_line("connections", int(index[1]))
    if " " in field:                    # "observer.u is not connected": the component's table
        return locator.line("components." + first.partition(".")[0]) if "." in first else None
    return locator.line(field)


def parse_system(text: str, path: str = "<system>", folder: Path = Path(".")) -> SystemSpec:
    """Check the system file ``text`` whole and make its FMU definitions (in memory: nothing is written).

    Parameters
    ----------
    text : str
        The file's contents.
    path : str
        How messages name the file (``dcmotor.toml``).
    folder : Path
        Where relative paths of the file (a ``csv`` source's, the report's reference) are read from.

    Returns
    -------
    SystemSpec
        The checked system, its designed gains in ``notes``.

    Raises
    ------
    ParameterError
        One line ``path:line: field: what is wrong`` (``path:line:column:`` for an expression).
    """
    locator = Locator(text)
    try:
        return _parse(text, path, folder, locator)
    except ParameterError as exc:
        message = str(exc)
        if message.startswith(path + ":"):
            raise
        line = _line_of(message.partition(": ")[0], locator)
        raise ParameterError(f"{path}:{line}: {message}" if line else f"{path}: {message}") from None


def _parse(text: str, path: str, folder: Path, locator: Locator) -> SystemSpec:
    for number, line in enumerate(text.split("\n"), start=1):
        for column, character in enumerate(line, start=1):
            if unicodedata.category(character) == "Cc" and character not in "\t\r":
                raise ParameterError(f"{path}:{number}:{column}: control character U+{ord(character):04X}; a "
                                     "system file is plain text")
            if character in BIDI_CONTROLS:
                raise ParameterError(f"{path}:{number}:{column}: bidirectional control character "
                                     f"U+{ord(character):04X}; it makes the file read otherwise than it is")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ParameterError(f"{path}: not valid TOML: {exc}") from None
    except RecursionError:
        raise ParameterError(f"{path}: not valid TOML: nested too deep") from None
    if not data:
        raise ParameterError(f"{path}: the file is empty; a system file needs at least name, [experiment] and "
                             "[components.NAME] tables (see 'obsfmu show --fields')")
    _unknown("", data, [f.name for f in TOP_FIELDS] + sorted(_SECTIONS))
    top, _ = _fields("", {k: v for k, v in data.items() if k not in _SECTIONS and k != "connections"},
                     TOP_FIELDS[:3])
    _identifier("name", top["name"])
    experiment = _experiment(data)
    context = Context(prefix="", name=top["name"], time_unit=top["time_unit"], folder=folder,
                      stop_time=experiment["stop_time"], step=experiment["step"])
    components = _components(data, context, locator, path)
    connections = check_connections(data.get("connections", []), components)
    values = check_values(_table("values", data.get("values", {})), components, connections)
    require_connected(components, connections, values)
    compares = check_compares(_compares(data), components)
    plotted = _plotted(data, components)
    reference = data.get("report", {}).get("reference")
    fastest = max(context.rates, default=None)
    _stamp_step_rate(components, fastest)
    return SystemSpec(top["name"], top["description"], top["time_unit"], components, connections, values,
                      experiment, compares, context.notes, path, None if reference is None else folder / reference,
                      fastest, plotted)


def _stamp_step_rate(components: dict, fastest: tuple[float, str] | None) -> None:
    """Give every continuous adaptive observer (an output ``converged``) the parameter ``step_rate``: the fastest
    rate of the system's dynamics and signals.  Its FMU then claims convergence only at communication steps
    whose coupling error ``(h step_rate)^2 / 3`` is within ``converged_tolerance`` (fmus/runtime/slave/step.py;
    the error bounds of the families cannot see the coupling error: a flag of 1 with a parameter error of
    0.15 at h = 0.5 s, issue 36).  Discrete observers (a sample time) sample exactly: none."""
    if fastest is None:
        return
    for spec in components.values():
        for definition in spec.definitions:
            names = {p.name for p in definition.parameters}
            if any(port.name == "converged" for port in definition.outputs) and not names & {"Ts", "sample_time"}:
                definition.parameters.append(Parameter.scalar(
                    "step_rate", fastest[0], f"fastest rate of the system ({fastest[1]}): converged stays 0 while "
                    "(h step_rate)^2 / 3 > converged_tolerance (step_rate in 1/time unit)"))


def load_system(path: Path | str) -> SystemSpec:
    """Read and check the system file ``path``.

    Parameters
    ----------
    path : Path or str
        The TOML file (UTF-8, at most :data:`MAX_FILE_BYTES`).

    Returns
    -------
    SystemSpec
        As :func:`parse_system`; relative paths in the file are read from its folder.

    Raises
    ------
    ParameterError
        The file cannot be read, is too big, or any mistake of :func:`parse_system`.
    """
    path = Path(path)
    try:
        with open(path, "rb") as handle:
            raw = handle.read(MAX_FILE_BYTES + 1)
    except FileNotFoundError:
        raise ParameterError(f"--config: file {path} does not exist") from None
    except IsADirectoryError:
        raise ParameterError(f"--config {path}: is a directory, expected a TOML file") from None
    except OSError as exc:
        raise ParameterError(f"--config {path}: cannot be read ({exc.strerror or exc})") from None
    if len(raw) > MAX_FILE_BYTES:
        raise ParameterError(f"{path}: more than {MAX_FILE_BYTES // 2 ** 20} MiB, the limit of a system file")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ParameterError(f"{path}: not a UTF-8 text file (byte {exc.start + 1})") from None
    return parse_system(text, str(path), path.parent)
