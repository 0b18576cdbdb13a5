"""The master's algorithm on the block objects themselves, without FMI: the "direct loop".

It is the yardstick of the FMU path (issue 14, target 1): the same blocks (built from the same
FMU definitions and start values by the same factories), the same Gauss-Seidel order, the same
input segments (value at ``t`` and a slope: interpolated from producers already stepped,
extrapolated from the previous communication point otherwise, held on the first step), the
same outputs read after every step and one recorded row per communication point.  What it
leaves out is exactly what the FMU path adds: the master's bookkeeping, ctypes, the C bridge and
the generic slave.  ``tests/benchmarks/test_benchmarks.py`` checks that both give the same trajectory.

    loop = DirectLoop(definitions, components, connections)
    times, rows = loop.run(stop_time, step)
"""

from __future__ import annotations

import numpy as np

from obsfmu.fmus.runtime.definition import FmuDefinition
from obsfmu.fmus.runtime.kinds import create_block, module_of
from obsfmu.fmus.master import Connection, communication_points
from obsfmu.observers.block import Segment

__all__ = ["DirectLoop", "for_scenario"]


def _parameters(definition: FmuDefinition, start: dict[str, float]) -> dict[str, np.ndarray]:
    """The factory's parameter arrays: the definition's values with ``start`` applied element-wise."""
    params, known = {}, set()
    for p in definition.parameters:
        flat = list(p.value)
        for i, name in enumerate(p.element_names):
            if name in start:
                flat[i] = float(start[name])
                known.add(name)
        params[p.name] = p.array(flat)
    unknown = set(start) - known - {n for port in definition.inputs for n in port.element_names}
    if unknown:
        raise ValueError(f"{definition.model_name}: start values of unknown parameters {sorted(unknown)}")
    return params


class _Node:
    """One block with its ports laid out as slices of flat vectors."""

    def __init__(self, name: str, definition: FmuDefinition, start: dict[str, float]):
        self.name = name
        self.block = create_block(definition.kind, _parameters(definition, start), definition.options,
                                  definition.kind_module or module_of(definition.kind))
        self.inputs = [(p.name, p.size) for p in definition.inputs]
        self.outputs = [(p.name, p.size) for p in definition.outputs]
        self.input_names = [n for p in definition.inputs for n in p.element_names]
        self.output_names = [n for p in definition.outputs for n in p.element_names]
        self.values = np.array([float(start.get(n, 0.0)) for n in self.input_names])  # unconnected: their start

    def split(self, flat: np.ndarray) -> dict[str, np.ndarray]:
        ports, offset = {}, 0
        for name, size in self.inputs:
            ports[name] = flat[offset:offset + size]
            offset += size
        return ports


def _elements(names: list[str], port: str) -> list[int]:
    if port in names:
        return [names.index(port)]
    found = [i for i, n in enumerate(names) if n.startswith(port + "[")]
    if not found:
        raise ValueError(f"no port {port!r} in {names}")
    return found


class DirectLoop:
    """Gauss-Seidel co-simulation of blocks in one process (see the module docstring).

    Parameters
    ----------
    definitions : list of FmuDefinition
        The FMUs' definitions (by model name).
    components : list of (instance, model name, start values)
        As in a :class:`~fmus.scenarios.Scenario`; stepped in this order.
    connections : list of Connection
    coupling : {"linear", "hold"}
    """

    def __init__(self, definitions, components, connections: list[Connection], coupling: str = "linear"):
        by_model = {d.model_name: d for d in definitions}
        self.nodes = [_Node(name, by_model[model], start) for name, model, start in components]
        self.linear = coupling == "linear"
        offsets, offset = {}, 0
        for node in self.nodes:
            offsets[node.name] = offset
            offset += len(node.output_names)
        self.size = offset
        rank = {node.name: i for i, node in enumerate(self.nodes)}
        nodes = {node.name: node for node in self.nodes}
        for i, node in enumerate(self.nodes):
            node.sources = np.zeros(len(node.input_names), dtype=int)
            node.connected = np.zeros(len(node.input_names), dtype=bool)
            node.stepped = np.zeros(len(node.input_names), dtype=bool)
        for connection in connections:
            (src, src_port), (dst, dst_port) = (c.split(".", 1) for c in (connection.source, connection.target))
            outs = _elements(nodes[src].output_names, src_port)
            ins = _elements(nodes[dst].input_names, dst_port)
            node = nodes[dst]
            node.sources[ins] = [offsets[src] + j for j in outs]
            node.connected[ins] = True
            node.stepped[ins] = rank[src] < rank[dst]
        for node in self.nodes:
            node.offset = offsets[node.name]

    def _read(self, node: _Node, t: float, live: np.ndarray, inputs: np.ndarray) -> None:
        outputs = node.block.outputs(t, node.split(inputs))
        offset = node.offset
        for name, size in node.outputs:
            live[offset:offset + size] = outputs[name]
            offset += size

    def run(self, stop_time: float, step: float, start_time: float = 0.0, ramp: int = 0, after_point=None):
        """Times and rows (every output of every block) at every communication point, ``t0`` included;
        ``after_point()`` is called after each step (as the master's ``should_stop``)."""
        live = np.zeros(self.size)
        for _ in range(len(self.nodes) + 1):                      # settle direct feedthrough at t0
            for node in self.nodes:
                node.values = np.where(node.connected, live[node.sources], node.values)
                self._read(node, start_time, live, node.values)
        times, rows = [start_time], [live.copy()]
        now, before, h_before = live.copy(), None, 0.0
        for t, h, t_next in communication_points(start_time, stop_time, step, ramp):
            slopes = (now - before) / h_before if before is not None else np.zeros_like(now)
            for node in self.nodes:
                src, connected = node.sources, node.connected
                if self.linear:
                    values = np.where(connected, now[src], node.values)
                    slope = np.where(connected, slopes[src], 0.0)
                    stepped = node.stepped
                    slope[stepped] = (live[src][stepped] - values[stepped]) / h
                else:
                    values, slope = np.where(connected, live[src], node.values), np.zeros(len(src))
                node.block.advance(t, h, {name: Segment(v.copy(), s.copy()) for (name, v), s in
                                          zip(node.split(values).items(), node.split(slope).values())})
                node.values = values + h * slope
                self._read(node, t + h, live, node.values)
            before, h_before, now = now, h, live.copy()
            rows.append(now)
            times.append(t_next)
            if after_point is not None:
                after_point()
        return np.array(times), np.array(rows)


def for_scenario(scenario) -> DirectLoop:
    """The direct loop of a :class:`~fmus.scenarios.Scenario` (default start values)."""
    definitions = [item[0] if isinstance(item, tuple) else item for item in scenario.definitions()]
    if scenario.order != "gauss-seidel":
        raise ValueError(f"{scenario.name}: the direct loop runs Gauss-Seidel only, not {scenario.order}")
    return DirectLoop(definitions, scenario.components, scenario.connections, scenario.coupling)
