"""FMI 3.0 FMUs in :mod:`fmus.master`: an instance adapter with the FMI 2.0 instance's interface.

The master works with FMI 2.0 element names and per-element value references (``_wire`` gives each
connected input the value reference of its variable).  :class:`Fmi3Instance` offers the same, over
fmpy's ``FMU3Slave``:

* ``variables`` maps every FMI 2.0 element name (``x_hat[2]``, ``u``; :mod:`fmus.fmi3.elements`) to a
  *slot*: its position in the instance's flat list of elements, used as its value reference by the
  master; inputs are kept per FMI 3.0 variable in a buffer (whole arrays are set, with the elements
  the master does not feed at their start values), outputs are read in one ``fmi3GetFloat64``;
* input derivatives (the master's ``coupling="linear"``) become the FMI 3.0 intermediate update:
  the FMU asks for its inputs at ``t + h`` during ``fmi3DoStep`` (docs/fmi3.md) and gets
  ``u(t) + h du`` -- the line FMI 2.0's ``fmi2SetRealInputDerivatives`` describes, so FMI 2.0 and
  FMI 3.0 FMUs of one definition give the same results to round-off;
* ``slave`` is a facade with the ``FMU2Slave`` methods the master calls (``setupExperiment``,
  ``enterInitializationMode``, ``getFMUstate``, ...), translated to FMI 3.0.

The calls of the stepping loop (``fmi3SetFloat64``, ``fmi3DoStep``, ``fmi3GetFloat64``) go to the
binary directly through ctypes functions with fixed argument types, on numpy buffers.

Both interfaces of the master's instance are served: ``set_inputs(values, derivatives)`` and
``refresh_outputs()`` (today's :mod:`fmus.master`), and ``prepare()``, ``bind_outputs(view)``,
``set_inputs(linear)`` on ``input_values``/``input_slopes``, ``do_step(t, h)`` returning FMI statuses
(the master's fast path).
"""

from __future__ import annotations

import re
import zipfile
from ctypes import POINTER, c_bool, c_double, c_int, c_size_t, c_void_p
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Slave

from .session import SimulationError, _Instance
from ..fmi3.elements import Element, elements

__all__ = ["Fmi3Instance", "fmi_version_of"]

_WARNING = 1  #: worst FMI status that lets a run go on
_VERSION = re.compile(rb'fmiVersion\s*=\s*"([0-9])')


def fmi_version_of(fmu) -> int:
    """2 or 3: the FMI version in the modelDescription.xml of ``fmu`` (read without parsing all of it)."""
    with zipfile.ZipFile(fmu) as archive, archive.open("modelDescription.xml") as description:
        match = _VERSION.search(description.read(4096))
    return int(match.group(1)) if match else 2


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
        self.set_float64 = self._function(dll, "fmi3SetFloat64", [pointer, pointer, size, pointer, size])
        self.get_float64 = self._function(dll, "fmi3GetFloat64", [pointer, pointer, size, pointer, size])
        flag, real = POINTER(c_bool), POINTER(c_double)
        self.do_step = self._function(dll, "fmi3DoStep", [pointer, c_double, c_double, c_bool, flag, flag, flag, real])

    @staticmethod
    def _function(dll, name, argtypes):
        function = dll[name]          # a new function object: fmpy's own keeps its argument types
        function.argtypes, function.restype = argtypes, c_int
        return function


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


class _Facade:
    """The ``FMU2Slave`` methods :mod:`fmus.master` calls, for an FMI 3.0 instance."""

    def __init__(self, owner: "Fmi3Instance"):
        self._owner = owner
        self._fmu = owner.fmu
        self._experiment = (0.0, None, None)

    def instantiate(self, callbacks=None, loggingOn=False):
        owner = self._owner
        owner.required = np.array(owner.required_inputs() if owner.can_interpolate else [], dtype=np.uint32)
        self._fmu.instantiate(loggingOn=loggingOn, logMessage=owner.log_message,
                              intermediateUpdate=owner.intermediate_update if len(owner.required) else None,
                              requiredIntermediateVariables=owner.required.tolist())
        owner.raw = _RawCalls(self._fmu.dll)
        owner.inputs.reset()

    def freeInstance(self):
        """Free the instance and unload the library, as fmpy's ``FMU2Slave.freeInstance`` does."""
        self._fmu.freeInstance()

    def freeLibrary(self):
        self._fmu.freeLibrary()

    def setupExperiment(self, tolerance=None, startTime=0.0, stopTime=None):
        self._experiment = (startTime, stopTime, tolerance)

    def enterInitializationMode(self):
        start, stop, tolerance = self._experiment
        self._fmu.enterInitializationMode(tolerance=tolerance, startTime=start, stopTime=stop)

    def exitInitializationMode(self):
        self._fmu.exitInitializationMode()

    def doStep(self, currentCommunicationPoint, communicationStepSize, noSetFMUStatePriorToCurrentPoint=True):
        status = self._owner.do_step(currentCommunicationPoint, communicationStepSize)
        if status > _WARNING:
            raise FMICallException(function="fmi3DoStep", status=status)

    def terminate(self):
        return self._fmu.terminate()

    def reset(self):
        self._fmu.reset()
        self._owner.inputs.reset()

    def getFMUstate(self):
        return self._fmu.getFMUState()

    def setFMUstate(self, state):
        self._fmu.setFMUState(state)

    def freeFMUstate(self, state):
        self._fmu.freeFMUState(state)


class Fmi3Instance(_Instance):
    """An instantiated FMI 3.0 FMU, addressed by FMI 2.0 element names (see the module docstring).

    A subclass of the master's FMI 2.0 instance for its name handling (``variable``, ``port``: the
    slots have FMI 2.0 element names); everything that calls the FMU is its own.
    """

    def __init__(self, component, directory, log):  # _Instance.__init__ (FMI 2.0) is not called
        self.name = component.name
        fmu = Path(component.fmu)
        self.description = read_model_description(str(fmu))
        if self.description.coSimulation is None:
            raise SimulationError(f"{self.name}: {fmu} is not a co-simulation FMU")
        self.slots = [_Slot(name, k, element) for k, (name, element) in enumerate(elements(self.description).items())]
        self.variables = {slot.name: slot for slot in self.slots}
        by_causality = {c: [v for v in self.description.modelVariables if v.causality == c]
                        for c in ("input", "output")}
        self.inputs = _Arrays(v for v in by_causality["input"] if v.type == "Float64")
        self._outputs = _Arrays(by_causality["output"])
        self.outputs = [s.name for s in self.slots if s.causality == "output"]
        self.output_vrs = [self.variables[n].valueReference for n in self.outputs]
        self.feedthrough = any(u.dependencies for u in self.description.outputs)
        capabilities = self.description.coSimulation
        self.can_interpolate = bool(getattr(capabilities, "providesIntermediateUpdate", False))
        self.can_save_state = bool(capabilities.canGetAndSetFMUstate)  # fmpy: one attribute name for FMI 2 and 3
        self._log = log
        self.fmu = FMU3Slave(guid=self.description.instantiationToken, unzipDirectory=str(directory),
                             modelIdentifier=capabilities.modelIdentifier, instanceName=self.name)
        self.slave = _Facade(self)
        self.raw: _RawCalls | None = None
        self.output_values = np.zeros(len(self.outputs))
        self.input_vrs: list[int] = []
        self.input_sources: np.ndarray = np.zeros(0, dtype=int)
        self.stepped_before: np.ndarray = np.zeros(0, dtype=bool)
        self.required = np.zeros(0, dtype=np.uint32)  # requiredIntermediateVariables (set at instantiation)
        self._slopes: np.ndarray | None = None  # per element of self.inputs, for the current step
        self._step_start = 0.0
        self._fast = False  # the master's fast path checks statuses; today's master expects exceptions
        self._flags = (c_bool(), c_bool(), c_bool(), c_double())
        self.instantiated = False

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

    def _wired(self) -> np.ndarray:
        """Where each wired input (``input_vrs``) is in :attr:`inputs`."""
        if getattr(self, "_input_index", None) is None or len(self._input_index) != len(self.input_vrs):
            self._input_index = np.array([self.inputs.offsets[self.slots[vr].element.variable]
                                          + self.slots[vr].element.index for vr in self.input_vrs], dtype=int)
        return self._input_index

    def prepare(self) -> None:
        """Buffers of the fast path (after wiring): input values and slopes, Gauss-Seidel indices."""
        self._fast = True
        self._wired()
        self.input_values = np.zeros(len(self.input_vrs))
        self.input_slopes = np.zeros(len(self.input_vrs))
        self.stepped_index = np.flatnonzero(self.stepped_before)
        self.stepped_sources = self.input_sources[self.stepped_index]

    def bind_outputs(self, view: np.ndarray) -> None:
        self.output_values = view

    def set_inputs(self, values=None, derivatives=None) -> int:
        """The wired inputs at the current time and, optionally, their slopes over the next step.

        Today's master: ``set_inputs(values, derivatives_or_None)``.  The fast path:
        ``set_inputs(linear)`` with :attr:`input_values` and :attr:`input_slopes` filled in.
        Returns the FMI status (fmpy raises before returning anything worse than a warning).
        """
        if isinstance(values, (bool, np.bool_)) or values is None:
            values, derivatives = self.input_values, (self.input_slopes if values else None)
        if not self.input_vrs:
            return 0
        wired = self._wired()
        self.inputs.values[wired] = values
        if derivatives is not None and self.can_interpolate:
            slopes = np.zeros_like(self.inputs.values)
            slopes[wired] = derivatives
            self._slopes = slopes
        else:
            self._slopes = None
        buffer = self.inputs.values
        status = self.raw.set_float64(self.fmu.component, self.inputs.vrs.ctypes.data, len(self.inputs.vrs),
                                      buffer.ctypes.data, len(buffer))
        return self._raise_if(status, "fmi3SetFloat64")

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
        return self._raise_if(status, "fmi3GetFloat64")

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
        """FMI 3.0 logMessage -> the master's logger (same entries as its FMI 2.0 instances)."""
        self._log._log(None, self.name.encode(), status, category, message.replace(b"##", b"#"))

    def _raise_if(self, status: int, function: str) -> int:
        """The status (fast path), or fmpy's exception for one worse than a warning (today's master)."""
        if status > _WARNING and not self._fast:
            raise FMICallException(function=function, status=status)
        return status
