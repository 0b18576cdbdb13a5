"""Fixed-step co-simulation master on fmpy's low-level FMI 2.0 API (``FMU2Slave``).

A :class:`System` is a list of FMU instances (:class:`Component`) and
connections ``"producer.output" -> "consumer.input"`` (whole ports such as
``plant.x`` or single elements such as ``plant.x[1]``).  :func:`cosimulate`
runs it with a fixed communication step in one of two orders:

* ``gauss-seidel`` -- instances step one after another in the listed order;
  each takes its inputs from the newest outputs (those of instances already
  stepped are at ``t + h``).
* ``jacobi`` -- every instance steps from the outputs at ``t``; direct
  feedthrough blocks are then re-evaluated so their outputs are consistent.

Coupling.  With ``coupling="linear"`` (default) the master sets every
connected input's ``<port>_interpolation`` parameter (when the FMU has one,
see :mod:`fmus.slave`): *interpolate* when the producer steps before the
consumer (Gauss-Seidel), *extrapolate* otherwise.  A held input lags by half
a step; the scenarios measure what that costs.  ``coupling="hold"`` keeps
the FMI default (zero-order hold).

Every output of every instance is recorded at every communication point,
``t0`` included, into a :class:`Result`.
"""

from __future__ import annotations

import difflib
import shutil
import sys
import tempfile
import time as wallclock
from ctypes import byref
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
from fmpy import calloc, free

from .result import Result

__all__ = ["Component", "Connection", "System", "SimulationError", "cosimulate", "ORDERS", "COUPLINGS"]

ORDERS = ("gauss-seidel", "jacobi")
COUPLINGS = ("linear", "hold")
_HOLD, _EXTRAPOLATE, _INTERPOLATE = 0, 1, 2
_STATUS = ["OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING"]


class SimulationError(RuntimeError):
    """A co-simulation could not be set up or an FMU refused a step."""


@dataclass
class Component:
    """One FMU instance: ``name`` (e.g. ``"plant"``), the ``.fmu`` file and start values."""

    name: str
    fmu: Path
    start: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class Connection:
    """``source`` output -> ``target`` input, each ``"instance.variable"``."""

    source: str
    target: str


@dataclass
class System:
    components: list[Component]
    connections: list[Connection]


def _closest(name: str, candidates) -> str:
    close = difflib.get_close_matches(name, list(candidates), n=3)
    return f"; did you mean {', '.join(close)}?" if close else ""


class _Instance:
    """An instantiated FMU with name -> value-reference maps and an output cache."""

    def __init__(self, component: Component, unzip_root: Path, log):
        self.name = component.name
        fmu = Path(component.fmu)
        if not fmu.is_file():
            raise SimulationError(f"{self.name}: FMU file {fmu} does not exist (run 'obsfmu build')")
        self.description = read_model_description(str(fmu))
        if self.description.coSimulation is None:
            raise SimulationError(f"{self.name}: {fmu} is not a co-simulation FMU")
        self.variables = {v.name: v for v in self.description.modelVariables}
        self.outputs = [v.name for v in self.description.modelVariables if v.causality == "output"]
        self.output_vrs = [self.variables[n].valueReference for n in self.outputs]
        self.feedthrough = any(u.dependencies for u in self.description.outputs)
        directory = extract(str(fmu), unzipdir=str(unzip_root / self.name))
        self._log = log
        self.slave = FMU2Slave(guid=self.description.guid, unzipDirectory=directory,
                               modelIdentifier=self.description.coSimulation.modelIdentifier,
                               instanceName=self.name)
        self.output_values = np.zeros(len(self.outputs))
        self.input_vrs: list[int] = []
        self.input_sources: np.ndarray = np.zeros(0, dtype=int)

    def variable(self, name: str):
        try:
            return self.variables[name]
        except KeyError:
            raise SimulationError(f"{self.name}.{name}: no such variable{_closest(name, self.variables)}") from None

    def port(self, name: str, causality: str) -> list[str]:
        """Element names of ``name`` (a scalar variable or a whole array port)."""
        if name in self.variables:
            names = [name]
        else:
            names = [n for n in self.variables if n.startswith(name + "[")]
            if not names:
                candidates = {n.split("[")[0] for n in self.variables if self.variables[n].causality == causality}
                raise SimulationError(f"{self.name}.{name}: no such {causality}{_closest(name, candidates)}")
        for n in names:
            if self.variables[n].causality != causality:
                raise SimulationError(f"{self.name}.{n}: is a {self.variables[n].causality}, "
                                      f"expected an {causality}")
        return names

    def set_value(self, name: str, value) -> None:
        variable = self.variable(name)
        vr = [variable.valueReference]
        if variable.type == "Real":
            self.slave.setReal(vr, [float(value)])
        elif variable.type in ("Integer", "Enumeration"):
            if float(value) != int(float(value)):
                raise SimulationError(f"{self.name}.{name}: expects an integer, got {value!r}")
            self.slave.setInteger(vr, [int(float(value))])
        elif variable.type == "Boolean":
            self.slave.setBoolean(vr, [str(value).lower() in ("1", "true")])
        else:
            raise SimulationError(f"{self.name}.{name}: type {variable.type} cannot be set")

    def refresh_outputs(self) -> None:
        if self.output_vrs:
            self.output_values[:] = self.slave.getReal(self.output_vrs)

    def pull_inputs(self, all_outputs: np.ndarray) -> None:
        if self.input_vrs:
            self.slave.setReal(self.input_vrs, all_outputs[self.input_sources].tolist())


class _Logger:
    """Collects FMU log messages; echoes warnings and errors to stderr."""

    def __init__(self, echo: bool):
        self.messages: list[tuple[str, str, str]] = []
        self.echo = echo
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        try:
            from fmpy.logging import addLoggerProxy
            addLoggerProxy(byref(self.callbacks))
        except Exception:  # pragma: no cover - fmpy without its logging proxy
            pass

    def _log(self, component, instance, status, category, message):
        entry = (instance.decode(errors="replace"), _STATUS[status] if status < 6 else str(status),
                 message.decode(errors="replace"))
        self.messages.append(entry)
        if self.echo and status >= 1:
            print(f"[{entry[1]}] {entry[0]}: {entry[2]}", file=sys.stderr)

    def last(self, instance: str, count: int = 3) -> str:
        mine = [m for i, _, m in (e for e in self.messages) if i == instance]
        return " | ".join(mine[-count:]) if mine else "no message logged"


class _Progress:
    """A one-line progress bar on stderr, shown only for runs longer than a second."""

    def __init__(self, enabled: bool, total: int):
        self.enabled, self.total = enabled, total
        self.start = wallclock.perf_counter()
        self.last_draw = 0.0
        self.drawn = False

    def update(self, done: int) -> None:
        if not self.enabled:
            return
        now = wallclock.perf_counter() - self.start
        if now < 1.0 or now - self.last_draw < 0.2:
            return
        self.last_draw = now
        fraction = done / self.total
        bar = "#" * int(30 * fraction)
        eta = now / max(fraction, 1e-9) - now
        print(f"\r[{bar:<30}] {100 * fraction:5.1f}%  {done}/{self.total} steps  eta {eta:5.1f} s",
              end="", file=sys.stderr, flush=True)
        self.drawn = True

    def close(self) -> None:
        if self.drawn:
            print(f"\r[{'#' * 30}] 100.0%  {self.total}/{self.total} steps  "
                  f"{wallclock.perf_counter() - self.start:.1f} s", file=sys.stderr)


def _wire(instances: dict[str, _Instance], connections: list[Connection]):
    """Element-wise (producer, output index) for every connected input; checks names and sizes."""
    offsets, offset = {}, 0
    for inst in instances.values():
        offsets[inst.name] = offset
        offset += len(inst.outputs)
    wires: dict[str, list[tuple[str, int, str]]] = {name: [] for name in instances}
    producers: dict[tuple[str, str], str] = {}
    for connection in connections:
        (src, src_var), (dst, dst_var) = (_split(connection.source), _split(connection.target))
        for inst_name in (src, dst):
            if inst_name not in instances:
                raise SimulationError(f"connection {connection.source} -> {connection.target}: unknown "
                                      f"instance {inst_name!r}{_closest(inst_name, instances)}")
        outputs = instances[src].port(src_var, "output")
        inputs = instances[dst].port(dst_var, "input")
        if len(outputs) != len(inputs):
            raise SimulationError(f"connection {connection.source} -> {connection.target}: "
                                  f"{len(outputs)} outputs vs {len(inputs)} inputs")
        for out_name, in_name in zip(outputs, inputs):
            if (dst, in_name) in producers:
                raise SimulationError(f"{dst}.{in_name}: connected twice")
            producers[(dst, in_name)] = src
            index = offsets[src] + instances[src].outputs.index(out_name)
            wires[dst].append((in_name, index, src))
    for name, inst in instances.items():
        inst.input_vrs = [inst.variable(in_name).valueReference for in_name, _, _ in wires[name]]
        inst.input_sources = np.array([index for _, index, _ in wires[name]], dtype=int)
    return wires


def _split(path: str) -> tuple[str, str]:
    instance, dot, variable = path.partition(".")
    if not dot or not variable:
        raise SimulationError(f"{path!r}: expected 'instance.variable'")
    return instance, variable


def _coupling_modes(instances, wires, order: str, coupling: str) -> dict[tuple[str, str], int]:
    """``<port>_interpolation`` value for every connected input port that has the parameter."""
    if coupling == "hold":
        return {}
    rank = {name: i for i, name in enumerate(instances)}
    modes = {}
    for consumer, connected in wires.items():
        for in_name, _, producer in connected:
            parameter = f"{in_name.split('[')[0]}_interpolation"
            if parameter not in instances[consumer].variables:
                continue
            stepped_before = order == "gauss-seidel" and rank[producer] < rank[consumer]
            modes[(consumer, parameter)] = _INTERPOLATE if stepped_before else _EXTRAPOLATE
    return modes


def cosimulate(system: System, stop_time: float, step: float, order: str = "gauss-seidel",
               start_time: float = 0.0, coupling: str = "linear", progress: bool = False,
               echo_log: bool = True) -> Result:
    """Run ``system`` from ``start_time`` to ``stop_time`` with communication step ``step``.

    Parameters
    ----------
    order : {"gauss-seidel", "jacobi"}
        Stepping order; Gauss-Seidel follows the order of ``system.components``.
    coupling : {"linear", "hold"}
        How inputs vary inside a step (see the module docstring).
    progress : bool
        Show a progress bar on stderr when the run takes longer than a second.

    Returns
    -------
    Result
        ``time`` and every output of every instance (``instance.variable``) at
        every communication point.
    """
    if order not in ORDERS:
        raise SimulationError(f"order: {order!r} is not one of {ORDERS}")
    if coupling not in COUPLINGS:
        raise SimulationError(f"coupling: {coupling!r} is not one of {COUPLINGS}")
    if not (np.isfinite(step) and step > 0):
        raise SimulationError(f"step: must be a positive number, got {step!r}")
    if not stop_time > start_time:
        raise SimulationError(f"stop_time: must be after start_time {start_time}, got {stop_time}")
    names = [c.name for c in system.components]
    if len(set(names)) != len(names):
        raise SimulationError(f"components: instance names must be unique, got {names}")
    steps = int(np.ceil((stop_time - start_time) / step - 1e-9))
    times = np.minimum(start_time + step * np.arange(steps + 1), stop_time)

    logger = _Logger(echo_log)
    unzip_root = Path(tempfile.mkdtemp(prefix="obsfmu_run_"))
    instances: dict[str, _Instance] = {}
    try:
        for component in system.components:
            instances[component.name] = _Instance(component, unzip_root, logger)
        wires = _wire(instances, system.connections)
        outputs = _bind_outputs(instances)
        for inst in instances.values():
            inst.slave.instantiate(callbacks=logger.callbacks, loggingOn=True)
        modes = _coupling_modes(instances, wires, order, coupling)
        columns = [f"{inst.name}.{out}" for inst in instances.values() for out in inst.outputs]
        values = np.empty((steps + 1, len(columns)))

        _initialize(instances, system.components, modes, start_time, stop_time, logger)
        values[0] = _all_outputs(instances)
        bar = _Progress(progress, steps)
        advance = _gauss_seidel_step if order == "gauss-seidel" else _jacobi_step
        for k in range(steps):
            h = step if k < steps - 1 else times[k + 1] - times[k]  # one step length: cached discretisations
            advance(instances, times[k], h, logger)
            values[k + 1] = _all_outputs(instances)
            if k % 256 == 0:
                bar.update(k + 1)
        bar.close()
        for inst in instances.values():
            inst.slave.terminate()
        return Result(times, columns, values)
    finally:
        for inst in instances.values():
            try:
                inst.slave.freeInstance()
                inst.slave.freeLibrary()
            except Exception:
                pass
        shutil.rmtree(unzip_root, ignore_errors=True)


def _bind_outputs(instances) -> np.ndarray:
    """One array for all outputs; each instance's ``output_values`` is a view into it."""
    shared = np.zeros(sum(len(inst.outputs) for inst in instances.values()))
    offset = 0
    for inst in instances.values():
        inst.output_values = shared[offset:offset + len(inst.outputs)]
        offset += len(inst.outputs)
    return shared


def _all_outputs(instances) -> np.ndarray:
    """The shared output array (a view: copy it to keep a snapshot)."""
    first = next(iter(instances.values()))
    return first.output_values.base if first.output_values.base is not None else first.output_values


def _call(inst: _Instance, logger: _Logger, what: str, function, *args):
    try:
        return function(*args)
    except Exception as exc:
        raise SimulationError(f"{inst.name}: {what} failed ({exc}); FMU says: {logger.last(inst.name)}") from None


def _settle_feedthrough(instances, logger, passes: int) -> None:
    """Propagate outputs to inputs until direct-feedthrough chains are consistent."""
    for _ in range(passes):
        outputs = _all_outputs(instances)
        for inst in instances.values():
            _call(inst, logger, "setting inputs", inst.pull_inputs, outputs)
            _call(inst, logger, "reading outputs", inst.refresh_outputs)
            outputs = _all_outputs(instances)


def _initialize(instances, components, modes, start_time, stop_time, logger) -> None:
    for inst in instances.values():
        _call(inst, logger, "setupExperiment", inst.slave.setupExperiment, None, start_time, stop_time)
        _call(inst, logger, "enterInitializationMode", inst.slave.enterInitializationMode)
    for (name, parameter), mode in modes.items():
        instances[name].set_value(parameter, mode)
    for component in components:
        inst = instances[component.name]
        for variable, value in component.start.items():
            inst.variable(variable)
            _call(inst, logger, f"setting {variable}={value}", inst.set_value, variable, value)
    _settle_feedthrough(instances, logger, len(instances) + 1)
    for inst in instances.values():
        _call(inst, logger, "exitInitializationMode", inst.slave.exitInitializationMode)
        _call(inst, logger, "reading outputs", inst.refresh_outputs)
    if not np.all(np.isfinite(_all_outputs(instances))):
        bad = [inst.name for inst in instances.values() if not np.all(np.isfinite(inst.output_values))]
        raise SimulationError(f"initial outputs of {bad} are not finite; FMU says: "
                              + " ; ".join(logger.last(b) for b in bad))


def _do_step(inst, logger, t, h) -> None:
    _call(inst, logger, f"doStep(t={t:.9g}, h={h:.3g})", inst.slave.doStep, t, h)
    inst.refresh_outputs()


def _gauss_seidel_step(instances, t, h, logger) -> None:
    for inst in instances.values():
        inst.pull_inputs(_all_outputs(instances))
        _do_step(inst, logger, t, h)


def _jacobi_step(instances, t, h, logger) -> None:
    outputs = _all_outputs(instances).copy()
    for inst in instances.values():
        inst.pull_inputs(outputs)
    for inst in instances.values():
        _do_step(inst, logger, t, h)
    if any(inst.feedthrough for inst in instances.values()):
        _settle_feedthrough(instances, logger, sum(inst.feedthrough for inst in instances.values()))
