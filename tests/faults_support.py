"""Helpers of the fault-injection tests: one FMU instance driven through fmpy's ``FMU2Slave``.

:class:`Probe` instantiates an FMU with a logger that keeps every message, records the status
of each FMI call instead of raising, and reads the complete state as bytes
(``fmi2SerializeFMUstate``) so that tests can check that a refused call changed nothing (the bytes
hold the binary's state machine state too: :func:`split_state`).
:func:`gauss_seidel` drives a scenario's instances in order, each consumer interpolating its
inputs from the producers' outputs (what the project's master does with ``--coupling linear``).
"""

from __future__ import annotations

import struct
from functools import lru_cache

import numpy as np
from fmpy import calloc, extract, free, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)

from obsfmu.fmus.scenarios import SCENARIOS, ensure_fmus
from obsfmu.fmus.runtime.state_format import decode, encode

OK, WARNING, DISCARD, ERROR, FATAL = 0, 1, 2, 3, 4
BAD_VALUES = [float("nan"), float("inf"), -float("inf"), 1e308, -1e308]


def split_state(data: bytes) -> tuple[str, bytes]:
    """FMU-state bytes -> (the FMI state machine state the binary kept in them, the identity and the
    encoded rest of the state).  The header is 24 bytes, then a 32-byte digest and the identity."""
    size = struct.unpack_from("<I", data, 12)[0]
    tree = decode(data[56 + size:])
    loader = tree.pop("loader")
    assert loader["fmi"] == 2, loader
    return loader["state"], data[56:56 + size] + encode(tree)


def one_per_kind(build_dir) -> dict[str, tuple[float, object]]:
    """``kind -> (scenario step, path)``: the first FMU of each block kind used by the scenarios."""
    kinds = {}
    for scenario in SCENARIOS.values():
        for item in scenario.definitions():
            definition = item[0] if isinstance(item, tuple) else item
            if definition.kind not in kinds:
                path = ensure_fmus(scenario, build_dir)[definition.model_name]
                kinds[definition.kind] = (scenario.step, path)
    return kinds


@lru_cache(maxsize=None)
def _description(path: str):
    return read_model_description(path)


@lru_cache(maxsize=None)
def _unzipped(path: str) -> str:
    return extract(path)


class Probe:
    """One instance of an FMU, initialised with ``start`` values (``init=False``: left in
    initialization mode)."""

    def __init__(self, path, name: str = "probe", start: dict | None = None, init: bool = True):
        self.path = str(path)
        self.description = _description(self.path)
        self.variables = {v.name: v for v in self.description.modelVariables}
        self.log: list[tuple[int, str]] = []
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self.slave = FMU2Slave(guid=self.description.guid, unzipDirectory=_unzipped(self.path),
                               modelIdentifier=self.description.coSimulation.modelIdentifier, instanceName=name)
        self.slave.instantiate(callbacks=self.callbacks, loggingOn=True)
        self.slave.setupExperiment(startTime=0.0)
        self.slave.enterInitializationMode()
        self.t = 0.0
        for variable, value in (start or {}).items():
            self.set(variable, value)
        if init:
            self.slave.exitInitializationMode()

    def _log(self, component, instance, status, category, message):
        self.log.append((status, message.decode(errors="replace").replace("%%", "%")))

    def messages(self, since: int = 0) -> str:
        return " | ".join(text for _, text in self.log[since:])

    def free(self) -> None:
        self.slave.freeInstance()

    # -- variables
    def names(self, causality: str) -> list[str]:
        return [v.name for v in self.description.modelVariables if v.causality == causality and v.type == "Real"]

    def vr(self, name: str) -> int:
        return self.variables[name].valueReference

    def set(self, name: str, value) -> int:
        if self.variables[name].type == "Integer":
            return self.call(self.slave.setInteger, [self.vr(name)], [int(value)])
        return self.call(self.slave.setReal, [self.vr(name)], [float(value)])

    def get(self, names) -> list[float]:
        return self.slave.getReal([self.vr(n) for n in names])

    def outputs(self) -> np.ndarray:
        return np.array(self.get(self.names("output")))

    # -- calls
    @staticmethod
    def call(function, *args) -> int:
        """Status of an FMI call (0 OK ... 4 fatal) instead of an exception."""
        try:
            function(*args)
        except FMICallException as exc:
            return exc.status
        return OK

    def drive_inputs(self, k: int, step: float) -> None:
        """A smooth deterministic signal on every input and its derivative (at ``t = k step``)."""
        names = self.names("input")
        if names:
            t = k * step
            self.slave.setReal([self.vr(n) for n in names], [0.1 * np.sin(0.7 * t + i) for i in range(len(names))])
            self.slave.setRealInputDerivatives([self.vr(n) for n in names], [1] * len(names),
                                               [0.07 * np.cos(0.7 * t + i) for i in range(len(names))])

    def step(self, h: float) -> int:
        status = self.call(self.slave.doStep, self.t, h)
        if status in (OK, WARNING):
            self.t += h
        return status

    def run(self, step: float, count: int) -> np.ndarray:
        """``count`` steps with :meth:`drive_inputs`; the outputs after each."""
        rows = []
        for _ in range(count):
            self.drive_inputs(int(round(self.t / step)), step)
            assert self.step(step) == OK, self.messages()
            rows.append(self.outputs())
        return np.array(rows)

    # -- state
    def state_bytes(self) -> bytes:
        state = self.slave.getFMUstate()
        data = bytes(self.slave.serializeFMUstate(state))
        self.slave.freeFMUstate(state)
        return data

    def assert_unchanged(self, before: bytes, machine: str = "stepComplete") -> None:
        """The state is bit for bit the one of ``before``, but the state machine is in ``machine``."""
        now, rest = split_state(self.state_bytes())
        assert (now, rest) == (machine, split_state(before)[1]), (now, machine)

    def restore_bytes(self, data: bytes, t: float | None = None) -> int:
        """Deserialise and set ``data`` (a state at time ``t``); the status of the failing call or OK."""
        try:
            state = self.slave.deSerializeFMUstate(data)
        except FMICallException as exc:
            return exc.status
        status = self.call(self.slave.setFMUstate, state)
        self.slave.freeFMUstate(state)
        if status == OK and t is not None:
            self.t = t
        return status


class LiveProbes:
    """One running instance per kind (3 steps in), created on demand and shared by a module's tests:
    ``live(kind) -> (probe, step, its state bytes then)``.  A refused call leaves it as it was."""

    def __init__(self, kind_fmus):
        self.kind_fmus, self.cache = kind_fmus, {}

    def __call__(self, kind: str):
        if kind not in self.cache:
            step, path = self.kind_fmus[kind]
            probe = Probe(path, kind)
            probe.run(step, 3)
            self.cache[kind] = probe, step, probe.state_bytes()
        return self.cache[kind]

    def free(self) -> None:
        for probe, _, _ in self.cache.values():
            probe.free()


def gauss_seidel(probes: dict[str, Probe], connections, h: float, count: int, record=()) -> dict[str, np.ndarray]:
    """``count`` Gauss-Seidel rounds in the order of ``probes``: each instance takes the newest
    outputs of its producers (set as values at the step end: ``<input>_interpolation = 2``,
    chosen by :func:`start_for_gauss_seidel`).  Returns the ``record`` variables after each round."""
    wires = [(c.source.split(".", 1), c.target.split(".", 1)) for c in connections]
    rows = {name: [] for name in record}
    for _ in range(count):
        for name, probe in probes.items():
            for (src, out), (dst, inp) in wires:
                if dst == name:
                    probe.set(inp, probes[src].get([out])[0])
            status = probe.step(h)
            assert status == OK, f"{name}: status {status}: {probe.messages()}"
        for name in record:
            instance, variable = name.split(".", 1)
            rows[name].append(probes[instance].get([variable])[0])
    return {name: np.array(values) for name, values in rows.items()}


def start_for_gauss_seidel(scenario, path_of) -> dict[str, Probe]:
    """Initialised instances of ``scenario`` with ``<input>_interpolation = 2`` on every connected
    input (the value set is the one at the step end) and the inputs at ``t = 0`` set from their
    producers before initialization ends (so the first step interpolates from them)."""
    interpolated = {}
    for connection in scenario.connections:
        instance, variable = connection.target.split(".", 1)
        interpolated.setdefault(instance, {})[f"{variable}_interpolation"] = 2
    probes = {instance: Probe(path_of[model], instance, start={**start, **interpolated.get(instance, {})},
                              init=False)
              for instance, model, start in scenario.components}
    for name, probe in probes.items():
        for connection in scenario.connections:
            (source, output), (target, variable) = connection.source.split(".", 1), connection.target.split(".", 1)
            if target == name:
                probe.set(variable, probes[source].get([output])[0])
        probe.slave.exitInitializationMode()
    return probes
