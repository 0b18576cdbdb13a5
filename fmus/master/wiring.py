"""Connections -> what each instance reads: its inputs' value references and their producers' outputs."""

from __future__ import annotations

import numpy as np

from .errors import SimulationError, closest
from .instance import Instance
from .system import Connection

__all__ = ["wire", "unconnected_inputs"]


def wire(instances: dict[str, Instance], connections: list[Connection]) -> set[tuple[str, str]]:
    """Resolve connections element-wise: each input gets the index of its producer's output.

    The shared output vector holds every instance's outputs in the order of ``instances``; each
    instance gets ``input_vrs``, ``input_sources`` (indices into that vector) and ``stepped_before``
    (its producer comes first in a Gauss-Seidel round), then prepares its buffers.  Returns the
    connected inputs as ``(instance, input element)`` pairs.
    """
    offset, offsets = 0, {}
    for inst in instances.values():
        offsets[inst.name] = offset
        offset += len(inst.outputs)
    rank = {name: i for i, name in enumerate(instances)}
    wires: dict[str, list[tuple[int, int, int]]] = {name: [] for name in instances}
    seen: set[tuple[str, str]] = set()
    for connection in connections:
        (src, src_var), (dst, dst_var) = _split(connection.source), _split(connection.target)
        for inst_name in (src, dst):
            if inst_name not in instances:
                raise SimulationError(f"connection {connection.source} -> {connection.target}: unknown "
                                      f"instance {inst_name!r}{closest(inst_name, instances)}")
        outputs = instances[src].port(src_var, "output")
        inputs = instances[dst].port(dst_var, "input")
        if len(outputs) != len(inputs):
            raise SimulationError(f"connection {connection.source} -> {connection.target}: "
                                  f"{len(outputs)} outputs vs {len(inputs)} inputs")
        for out_name, in_name in zip(outputs, inputs):
            if (dst, in_name) in seen:
                raise SimulationError(f"{dst}.{in_name}: connected twice")
            seen.add((dst, in_name))
            source = offsets[src] + instances[src].outputs.index(out_name)
            wires[dst].append((instances[dst].variable(in_name).valueReference, source, rank[src]))
    for name, inst in instances.items():
        wires[name].sort()           # by value reference: an obsfmu FMU's declaration order, its fastest step
        inst.input_vrs = [vr for vr, _, _ in wires[name]]
        inst.input_sources = np.array([source for _, source, _ in wires[name]], dtype=int)
        inst.stepped_before = np.array([producer < rank[name] for _, _, producer in wires[name]], dtype=bool)
        inst.prepare()
    return seen


def unconnected_inputs(instances: dict[str, Instance], connected: set[tuple[str, str]],
                       given: dict[str, dict]) -> list[str]:
    """``instance.input`` of every input neither connected nor given a start value in ``given[instance]``."""
    return [f"{name}.{variable}" for name, inst in instances.items()
            for variable, description in inst.variables.items()
            if description.causality == "input" and (name, variable) not in connected
            and variable not in given.get(name, {})]


def _split(path: str) -> tuple[str, str]:
    instance, dot, variable = path.partition(".")
    if not dot or not variable:
        raise SimulationError(f"{path!r}: expected 'instance.variable'")
    return instance, variable
