"""Connections, explicit input values and comparisons of a system file, checked against the ports.

A connection ``"a.y -> b.u"`` joins whole ports (of one size) or elements (``a.y[2] -> b.u[1]``,
indexed from 1).  Every input element must be connected once, or given in ``[values]``: otherwise
the error names it ("observer.u is not connected: connect it or give it a value in [values]").
"""

from __future__ import annotations

import difflib
import re

import numpy as np

from obsfmu.observers.checks import ParameterError

from ..master import Connection
from ..runtime.definition import Port
from .values import check_text

__all__ = ["check_connections", "check_values", "require_connected", "check_compares", "ports", "elements",
           "MAX_CONNECTIONS"]

MAX_CONNECTIONS = 10_000
_END = r"\s*([A-Za-z_]\w*)\.([A-Za-z_]\w*)(?:\[(\d{1,6})\])?\s*"
_CONNECTION = re.compile(_END + "->" + _END)
_REFERENCE = re.compile(_END)


def ports(spec, causality: str) -> dict[str, Port]:
    """The input (``causality="input"``) or output ports of a component, by name."""
    return {port.name: port for d in spec.definitions for port in (d.inputs if causality == "input" else d.outputs)}


def _hint(name: str, known) -> str:
    close = difflib.get_close_matches(name, list(known), n=1)
    return f"; did you mean {close[0]!r}?" if close else f"; known: {', '.join(known) or 'none'}"


def elements(where: str, components: dict, instance: str, port: str, index: str | None, causality: str) -> list[str]:
    """The FMU variable names of ``instance.port`` (or of its element ``index``, from 1)."""
    if instance not in components:
        raise ParameterError(f"{where}: unknown component {instance!r}{_hint(instance, components)}")
    known = ports(components[instance], causality)
    if port not in known:
        other = "output" if causality == "input" else "input"
        also = f" ({port!r} is an {other})" if port in ports(components[instance], other) else ""
        raise ParameterError(f"{where}: {instance} has no {causality} {port!r}{also}{_hint(port, known)}")
    names = known[port].element_names
    if index is None:
        return names
    if not 1 <= int(index) <= len(names):
        raise ParameterError(f"{where}: {instance}.{port}[{index}] is out of range; {instance}.{port} has "
                             f"{len(names)} entr{'y' if len(names) == 1 else 'ies'}")
    return [names[int(index) - 1]]


def check_connections(items, components: dict) -> list[Connection]:
    """The file's ``connections`` checked against the components' ports.

    Parameters
    ----------
    items : list of str
        ``"a.y -> b.u"``, ``"a.y[2] -> b.u[1]"``.
    components : dict
        Instance name -> :class:`~fmus.system.model.ComponentSpec`.

    Returns
    -------
    list of fmus.master.Connection
        One per connection of whole ports, one per element otherwise.

    Raises
    ------
    ParameterError
        ``connections[i]``: unknown component or port (did-you-mean), index out of range, sizes that
        differ, an input connected twice.
    """
    if not isinstance(items, list):
        raise ParameterError('connections: expected a list of "a.y -> b.u" texts')
    if len(items) > MAX_CONNECTIONS:
        raise ParameterError(f"connections: {len(items)} connections, more than the limit of {MAX_CONNECTIONS}")
    result, seen = [], set()
    for i, item in enumerate(items, start=1):
        where = f"connections[{i}]"
        match = _CONNECTION.fullmatch(check_text(where, item))
        if not match:
            raise ParameterError(f'{where}: {item!r} is not "a.y -> b.u" (component.port, optionally [index])')
        source = elements(where, components, *match.group(1, 2, 3), "output")
        target = elements(where, components, *match.group(4, 5, 6), "input")
        if len(source) != len(target):
            raise ParameterError(f"{where}: {item.strip()!r} joins {len(source)} outputs to {len(target)} inputs; "
                                 "connect ports of one size, or elements ([i])")
        for out_name, in_name in zip(source, target):
            key = f"{match[4]}.{in_name}"
            if key in seen:
                raise ParameterError(f"{where}: {key} is connected twice")
            seen.add(key)
            result.append(Connection(f"{match[1]}.{out_name}", key))
    return result


def _flat(table: dict, prefix: str = "") -> dict:
    """``{"a": {"u": 1}}`` (unquoted dotted keys) and ``{"a.u": 1}`` alike as ``{"a.u": 1}``."""
    flat = {}
    for key, value in table.items():
        name = f"{prefix}{key}"
        flat.update(_flat(value, name + ".") if isinstance(value, dict) else {name: value})
    return flat


def check_values(table: dict, components: dict, connections: list[Connection]) -> dict[str, dict[str, float]]:
    """``[values]``: per component, the start value of each unconnected input element it gives."""
    connected = {c.target for c in connections}
    result: dict[str, dict[str, float]] = {}
    for key, value in _flat(table).items():
        where = f"values.{key}"
        match = _REFERENCE.fullmatch(check_text(where, key))
        if not match:
            raise ParameterError(f"{where}: expected component.input or component.input[i]")
        names = elements(where, components, *match.group(1, 2, 3), "input")
        numbers = value if isinstance(value, list) else [value] * len(names)
        if len(numbers) != len(names) or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                 and np.isfinite(v) for v in numbers):
            raise ParameterError(f"{where}: expected a finite number or a list of {len(names)}, got {value!r:.60}")
        for name, number in zip(names, numbers):
            if f"{match[1]}.{name}" in connected:
                raise ParameterError(f"{where}: {match[1]}.{name} is connected; its value comes from the connection")
            result.setdefault(match[1], {})[name] = float(number)
    return result


def require_connected(components: dict, connections: list[Connection], values: dict) -> None:
    """Every input element is connected or has a value; else the error names the first one missing."""
    connected = {c.target for c in connections}
    for instance, spec in components.items():
        for port in ports(spec, "input").values():
            missing = [n for n in port.element_names
                       if f"{instance}.{n}" not in connected and n not in values.get(instance, {})]
            if missing:
                name = port.name if len(missing) == port.size else missing[0]
                raise ParameterError(f"{instance}.{name} is not connected: connect it or give it a value in [values]")


def check_compares(compares: list[dict], components: dict) -> list[dict]:
    """``[[report.compare]]``: estimate and truth are output ports (or elements) of one size."""
    for i, compare in enumerate(compares, start=1):
        sizes = {}
        for key in ("estimate", "truth"):
            where = f"report.compare[{i}].{key}"
            match = _REFERENCE.fullmatch(compare[key])
            if not match:
                raise ParameterError(f"{where}: expected component.output or component.output[i]")
            compare[key + "_columns"] = [f"{match[1]}.{n}" for n in
                                         elements(where, components, *match.group(1, 2, 3), "output")]
            sizes[key] = len(compare[key + "_columns"])
        if sizes["estimate"] != sizes["truth"]:
            raise ParameterError(f"report.compare[{i}].truth: {compare['truth']} has {sizes['truth']}, "
                                 f"{compare['estimate']} has {sizes['estimate']} (compare ports of one size)")
        if compare["tolerance"] <= 0:
            raise ParameterError(f"report.compare[{i}].tolerance: must be > 0")
    return compares


def check_plotted(signals, components: dict) -> list[list[str]]:
    """``[plot] signals``: outputs (``component.output`` or ``component.output[i]``) drawn in panels of their own
    beside the comparisons; the columns of each."""
    if not isinstance(signals, list) or not all(isinstance(s, str) for s in signals):
        raise ParameterError("plot.signals: expected a list of texts \"component.output\" or \"component.output[i]\"")
    panels = []
    for i, signal in enumerate(signals, start=1):
        where = f"plot.signals[{i}]"
        match = _REFERENCE.fullmatch(signal)
        if not match:
            raise ParameterError(f"{where}: expected component.output or component.output[i], got {signal!r:.60}")
        panels.append([f"{match[1]}.{n}" for n in elements(where, components, *match.group(1, 2, 3), "output")])
    return panels

