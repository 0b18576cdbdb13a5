"""FMI 3.0 FMUs in the master: :class:`Fmi3Instance` on fmpy's ``FMU3Slave``, with the interface of the others.

The master works with FMI 2.0 element names and per-element value references (wiring gives each
connected input the value reference of its variable).  :class:`Fmi3Instance` offers the same:

* ``variables`` maps every FMI 2.0 element name (``x_hat[2]``, ``u``; :mod:`fmus.fmi3.elements`) to a
  *slot*: its position in the instance's flat list of elements, used as its value reference by the
  master; inputs are kept per FMI 3.0 variable in a buffer (whole arrays are set, with the elements
  the master does not feed at their start values), outputs are read in one ``fmi3GetFloat64``;
* input derivatives (the master's ``coupling="linear"``) become the FMI 3.0 intermediate update:
  the FMU asks for its inputs at ``t + h`` during ``fmi3DoStep`` (docs/fmi3.md) and gets
  ``u(t) + h du`` -- the line FMI 2.0's ``fmi2SetRealInputDerivatives`` describes, so FMI 2.0 and
  FMI 3.0 FMUs of one definition give the same results to round-off.

The calls of the stepping loop (``fmi3SetFloat64``, ``fmi3DoStep``, ``fmi3GetFloat64``) go to the
binary directly through ctypes functions with fixed argument types, on numpy buffers.
"""

from __future__ import annotations

from ctypes import POINTER, c_bool, c_double, c_size_t, c_void_p
from dataclasses import dataclass

import numpy as np
from fmpy.fmi3 import FMU3Slave

from ..fmi3.elements import Element, elements
from .errors import SimulationError
from .instance import Instance, fixed_function

__all__ = ["Fmi3Instance"]


@dataclass(frozen=True)
class _Slot:
    """An element as the master sees it: ``valueReference`` is its position in :attr:`Fmi3Instance.slots`."""

    name: str
    valueReference: int
    element: Element

    @property
    def causality(self) -> str:
        return self.element.causality

    @property
    def type(self) -> str:
        return self.element.type


class _RawCalls:
    """The FMI 3.0 functions of the stepping loop, called on the binary directly (fixed argument types)."""

    def __init__(self, dll):
        pointer, size = c_void_p, c_size_t
        self.set_float64 = fixed_function(dll, "fmi3SetFloat64", [pointer, pointer, size, pointer, size])
        self.get_float64 = fixed_function(dll, "fmi3GetFloat64", [pointer, pointer, size, pointer, size])
        flag, real = POINTER(c_bool), POINTER(c_double)
        self.do_step = fixed_function(dll, "fmi3DoStep", [pointer, c_double, c_double, c_bool, flag, flag, flag, real])


class _Arrays:
    """Some FMI 3.0 variables of one type as one flat buffer (their value references and elements)."""

    def __init__(self, variables):
        self.variables = list(variables)
        self.vrs = np.array([v.valueReference for v in self.variables], dtype=np.uint32)
        self.offsets = {v.name: offset for v, offset in zip(self.variables, np.cumsum([0] + [_size(v) for v in
                                                                                          self.variables]))}
        self.values = np.zeros(sum(_size(v) for v in self.variables))

    def reset(self) -> None:
        """Every element at its declared start value."""
        for variable in self.variables:
            offset = self.offsets[variable.name]
            self.values[offset:offset + _size(variable)] = [float(x) for x in (variable.start or "0").split()]


def _size(variable) -> int:
    return int(np.prod([int(d.start) for d in variable.dimensions])) if variable.dimensions else 1


class Fmi3Instance(Instance):
    """An instantiated FMI 3.0 FMU, addressed by FMI 2.0 element names (see the module docstring)."""

    def __init__(self, name: str, description, directory, logger):
        super().__init__(name, description, logger)
        self.slots = [_Slot(element_name, k, element)
                      for k, (element_name, element) in enumerate(elements(description).items())]
        self.variables = {slot.name: slot for slot in self.slots}
        by_causality = {c: [v for v in description.modelVariables if v.causality == c] for c in ("input", "output")}
        self.inputs = _Arrays(v for v in by_causality["input"] if v.type == "Float64")
        self._outputs = _Arrays(by_causality["output"])
        self.outputs = [s.name for s in self.slots if s.causality == "output"]
        self.output_vrs = [self.variables[n].valueReference for n in self.outputs]
        capabilities = description.coSimulation
        self.can_interpolate = bool(getattr(capabilities, "providesIntermediateUpdate", False))
        self.fmu = FMU3Slave(guid=description.instantiationToken, unzipDirectory=str(directory),
                             modelIdentifier=capabilities.modelIdentifier, instanceName=name)
        self.raw: _RawCalls | None = None
        self.output_values = np.zeros(len(self.outputs))
        self.required = np.zeros(0, dtype=np.uint32)  # requiredIntermediateVariables (set at instantiation)
        self._slopes: np.ndarray | None = None  # per element of self.inputs, for the current step
        self._step_start = 0.0
        self._flags = (c_bool(), c_bool(), c_bool(), c_double())
        self._experiment = (0.0, None, None)

    def required_inputs(self) -> list[int]:
        """FMI 3.0 value references of the inputs the master feeds (requiredIntermediateVariables)."""
        fed = {self.slots[vr].element.variable for vr in self.input_vrs}
        return [int(vr) for v, vr in zip(self.inputs.variables, self.inputs.vrs) if v.name in fed]

    # ------------------------------------------------------------------ values
    def set_value(self, name: str, value) -> None:
        """A start value, by element name: the element's variable is set whole."""
        element = self.variable(name).element
        vr = [element.valueReference]
        if element.type == "Integer":
            if float(value) != int(float(value)):
                raise SimulationError(f"{self.name}.{name}: expects an integer, got {value!r}")
            self.fmu.setInt32(vr, [int(float(value))])
        elif element.type == "Real":
            if element.causality == "input" and element.variable in self.inputs.offsets:
                self.inputs.values[self.inputs.offsets[element.variable] + element.index] = float(value)
            values = self.fmu.getFloat64(vr, nValues=element.size)
            values[element.index] = float(value)
            self.fmu.setFloat64(vr, values)
        else:
            raise SimulationError(f"{self.name}.{name}: type {element.type} cannot be set")

    def prepare(self) -> None:
        """Buffers of the stepping loop (after wiring); where each wired input is in :attr:`inputs`."""
        super().prepare()
        self._input_index = np.array([self.inputs.offsets[self.slots[vr].element.variable]
                                      + self.slots[vr].element.index for vr in self.input_vrs], dtype=int)

    def set_inputs(self, derivatives: bool = False) -> int:
        """The wired inputs (:attr:`input_values`) and, with ``derivatives``, their slopes over the next step
        (:attr:`input_slopes`, given to the FMU in the intermediate update); the FMI status."""
        if not self.input_vrs:
            return 0
        wired = self._input_index
        self.inputs.values[wired] = self.input_values
        if derivatives and self.can_interpolate:
            slopes = np.zeros_like(self.inputs.values)
            slopes[wired] = self.input_slopes
            self._slopes = slopes
        else:
            self._slopes = None
        buffer = self.inputs.values
        return self.raw.set_float64(self.fmu.component, self.inputs.vrs.ctypes.data, len(self.inputs.vrs),
                                    buffer.ctypes.data, len(buffer))

    def refresh_outputs(self) -> int:
        """``fmi3GetFloat64`` of every output into :attr:`output_values`; the FMI status."""
        if not self.outputs:
            return 0
        target = self.output_values
        contiguous = target.flags["C_CONTIGUOUS"]
        buffer = target if contiguous else np.empty(len(target))
        status = self.raw.get_float64(self.fmu.component, self._outputs.vrs.ctypes.data, len(self._outputs.vrs),
                                      buffer.ctypes.data, len(buffer))
        if not contiguous:
            target[:] = buffer
        return status

    def do_step(self, t: float, h: float) -> int:
        """``fmi3DoStep(t, h)``, its status: the FMU asks for the inputs at ``t + h`` (:meth:`intermediate_update`)."""
        self._step_start = t
        event, terminate, early, last = self._flags
        return self.raw.do_step(self.fmu.component, t, h, True, event, terminate, early, last)

    def intermediate_update(self, environment, time, set_requested, get_allowed, finished, can_return_early,
                            early_return_requested, early_return_time) -> None:
        """The intermediate update (inside ``fmi3DoStep``): the inputs at ``time`` on their lines."""
        if not set_requested or self._slopes is None:
            return  # hold coupling: the inputs set at t remain (or the <port>_interpolation modes decide)
        ends = self.inputs.values + (time - self._step_start) * self._slopes
        required = self.required
        if len(required) == len(self.inputs.vrs):
            self.raw.set_float64(self.fmu.component, required.ctypes.data, len(required), ends.ctypes.data, len(ends))
            return
        for variable, vr in zip(self.inputs.variables, self.inputs.vrs):
            if vr in required:
                offset = self.inputs.offsets[variable.name]
                part = np.ascontiguousarray(ends[offset:offset + _size(variable)])
                single = np.array([vr], dtype=np.uint32)
                self.raw.set_float64(self.fmu.component, single.ctypes.data, 1, part.ctypes.data, len(part))

    def log_message(self, environment, status, category, message) -> None:
        """FMI 3.0 logMessage -> the session's logger (same entries as its FMI 2.0 instances)."""
        self._log.log(None, self.name.encode(), status, category, message.replace(b"##", b"#"))

    # ------------------------------------------------------------------ life cycle (fmpy)
    def instantiate(self) -> None:
        self.required = np.array(self.required_inputs() if self.can_interpolate else [], dtype=np.uint32)
        self.fmu.instantiate(loggingOn=True, logMessage=self.log_message,
                             intermediateUpdate=self.intermediate_update if len(self.required) else None,
                             requiredIntermediateVariables=self.required.tolist())
        self.raw = _RawCalls(self.fmu.dll)
        self.inputs.reset()
        self.instantiated = True

    def setup_experiment(self, start_time: float, stop_time: float) -> None:
        self._experiment = (start_time, stop_time, None)     # FMI 3.0: given when entering initialization

    def enter_initialization_mode(self) -> None:
        start, stop, tolerance = self._experiment
        self.fmu.enterInitializationMode(tolerance=tolerance, startTime=start, stopTime=stop)

    def exit_initialization_mode(self) -> None:
        self.fmu.exitInitializationMode()

    def terminate(self) -> None:
        self.fmu.terminate()

    def reset(self) -> None:
        self.fmu.reset()
        self.inputs.reset()

    def get_state(self):
        return self.fmu.getFMUState()

    def set_state(self, state) -> None:
        self.fmu.setFMUState(state)

    def free_state(self, state) -> None:
        self.fmu.freeFMUState(state)

    def _free_instance(self) -> None:
        self.fmu.freeInstance()           # and unloads the library, as fmpy's FMU2Slave.freeInstance does

    def _free_library(self) -> None:
        self.fmu.freeLibrary()
