"""The one generic FMI 2.0 co-simulation slave: any block becomes an FMU.

Every FMU of the project contains a two-line module::

    from fmus.slave import BlockSlave
    class ship_observer(BlockSlave):
        definition_file = "ship_observer.json"

and the definition file (:mod:`fmus.definition`).  This class turns the
definition into FMI variables, builds the block from the parameter values
when they are first needed (so values set by the importer before or during
initialization take effect), and advances it in ``do_step``.

Inputs inside a communication step
----------------------------------
FMI hands an FMU one input value per communication step.  Holding it
constant over ``[t, t + h]`` lags the signal by ``h/2``, which costs the
observers of this project more accuracy than any tuning gains.  Every input
port ``p`` of a dynamic block therefore has an Integer parameter
``p_interpolation``:

* ``0`` hold -- the value set before ``do_step(t, h)`` is held (FMI default);
* ``1`` extrapolate -- the value is the one at ``t``; the slope comes from the
  previous communication point (for Jacobi/parallel masters, or when the
  producer of the signal steps *after* this FMU);
* ``2`` interpolate -- the value is the one at ``t + h`` (Gauss-Seidel with the
  producer stepped *before* this FMU); the input follows the line from the
  previous value.

An importer that sends ``fmi2SetRealInputDerivatives`` (the project's master
does) overrides the mode for that step: the input follows its derivative.
The parameters serve importers that cannot (libcosim, ECOS: ``obsfmu export``
sets 1 for them).

Errors never crash the host: a bad parameter set makes
``exit_initialization_mode`` raise (fmi2Error through the native binary); a
NaN/inf input or a failure inside the block is logged (at Discard level) and
``do_step`` returns fmi2Discard with the state unchanged.
"""

from __future__ import annotations

import copy
import io
import pickle
from enum import IntEnum
from pathlib import Path
from typing import ClassVar
from xml.etree.ElementTree import Element, SubElement

import numpy as np
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.enums import Fmi2Status
from pythonfmu.default_experiment import DefaultExperiment

from observers.block import Block, Segment
from observers.checks import ParameterError, finite_signal

from .bundle import portable_name
from .definition import FmuDefinition, element_unit
from .kinds import create_block

__all__ = ["BlockSlave", "InputMode", "CAPABILITIES"]


class InputMode(IntEnum):
    """Value of the ``<port>_interpolation`` parameters."""

    HOLD = 0
    EXTRAPOLATE = 1
    INTERPOLATE = 2


#: what the native binary (fmus/native) and this class really support
CAPABILITIES = {
    "needsExecutionTool": "true",  # a Python interpreter with numpy and scipy
    "canHandleVariableCommunicationStepSize": "true",
    "canInterpolateInputs": "true",
    "maxOutputDerivativeOrder": "0",
    "canRunAsynchronuously": "false",
    "canBeInstantiatedOnlyOncePerProcess": "false",
    "canNotUseMemoryManagementFunctions": "true",
    "canGetAndSetFMUstate": "true",
    "canSerializeFMUstate": "true",
    "providesDirectionalDerivative": "false",
}

_EXTRAPOLATE, _INTERPOLATE = int(InputMode.EXTRAPOLATE), int(InputMode.INTERPOLATE)


class _StateUnpickler(pickle.Unpickler):
    """Loads FMU states only: numpy arrays and the project's own classes, nothing else."""

    _ALLOWED_ROOTS = ("numpy", "observers", "plants", "fmus")
    _ALLOWED_BUILTINS = {"complex", "slice", "range", "set", "frozenset", "bytearray"}

    def find_class(self, module, name):
        root = portable_name(module).split(".")[0]
        if root in self._ALLOWED_ROOTS or (module == "builtins" and name in self._ALLOWED_BUILTINS) or (
                module == "collections" and name in ("OrderedDict", "deque")):
            return super().find_class(module, name)
        raise pickle.UnpicklingError(f"FMU state may not contain {module}.{name}")


def interpolation_parameter(port: str) -> str:
    return f"{port}_interpolation"


class BlockSlave(Fmi2Slave):
    """Generic adapter from a :class:`~observers.block.Block` to ``pythonfmu``."""

    definition_file: ClassVar[str] = ""
    author = "obsfmu"
    license = "MIT"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        definition = FmuDefinition.load(Path(self.resources) / self.definition_file)
        self.definition = definition
        self.modelName = definition.model_name
        self.description = definition.description
        if definition.default_experiment:
            self.default_experiment = DefaultExperiment(**definition.default_experiment)

        self._params = {p.name: np.array(p.value, dtype=float) for p in definition.parameters}
        self._inputs = {p.name: np.zeros(p.size) for p in definition.inputs}
        self._modes = {p.name: np.zeros(1, dtype=int) for p in definition.inputs}
        self._units: dict[str, str] = {}
        self._block: Block | None = None
        self._block_error: str | None = None
        self._outputs_cache: dict[str, np.ndarray] | None = None
        self._time = 0.0
        self._stepping = False
        self._last_inputs: dict[str, tuple[np.ndarray, float]] = {}
        self._derivatives: dict[str, np.ndarray] = {}  # first input derivatives for the next step
        self._input_elements: dict[int, tuple[str, int]] = {}  # value reference -> (port, index)

        for p in definition.parameters:
            self._register_array(p.element_names, self._params[p.name], Fmi2Causality.parameter,
                                 p.description, p.unit, on_set=self._parameters_changed)
        if not self._stateless():
            for port in definition.inputs:
                self._register_mode(port.name)
        for port in definition.inputs:
            references = self._register_array(port.element_names, self._inputs[port.name], Fmi2Causality.input,
                                              port.description, port.unit, on_set=self._inputs_changed)
            self._input_elements.update({vr: (port.name, i) for i, vr in enumerate(references)})
        for port in definition.outputs:
            self._register_outputs(port)

    # ------------------------------------------------------------------ variables
    def _register_array(self, names, store: np.ndarray, causality, description, unit, on_set) -> list[int]:
        variability = Fmi2Variability.fixed if causality == Fmi2Causality.parameter else Fmi2Variability.continuous
        references = []
        for i, name in enumerate(names):
            def setter(value, i=i, name=name):
                store[i] = value
                on_set(name)
            variable = Real(name, causality=causality, variability=variability, description=description,
                            getter=lambda i=i: float(store[i]), setter=setter)
            self.register_variable(variable)
            references.append(variable.value_reference)
            if element_unit(unit, i):
                self._units[name] = element_unit(unit, i)
        return references

    def _register_mode(self, port: str):
        store = self._modes[port]

        def setter(value):
            if int(value) not in InputMode._value2member_map_:
                self.log(f"{interpolation_parameter(port)}: {value} is not 0 (hold), 1 (extrapolate) "
                         f"or 2 (interpolate); keeping {int(store[0])}", Fmi2Status.error)
                return
            store[0] = int(value)

        self.register_variable(Integer(
            interpolation_parameter(port), causality=Fmi2Causality.parameter,
            variability=Fmi2Variability.fixed,
            description=f"input {port} inside a step: 0 hold, 1 extrapolate from the previous point "
                        f"(value at step start), 2 interpolate (value at step end, Gauss-Seidel)",
            getter=lambda: int(store[0]), setter=setter))

    def _register_outputs(self, port):
        for i, name in enumerate(port.element_names):
            self.register_variable(Real(name, causality=Fmi2Causality.output,
                                        variability=Fmi2Variability.continuous,
                                        description=port.description,
                                        getter=lambda p=port.name, i=i: self._output(p, i)))
            if element_unit(port.unit, i):
                self._units[name] = element_unit(port.unit, i)

    def _parameters_changed(self, name):
        if self._stepping:
            self.log(f"{name}: parameters are fixed after initialization; the new value is ignored "
                     f"by the running block", Fmi2Status.warning)
            return
        self._block = None
        self._block_error = None
        self._outputs_cache = None

    def _inputs_changed(self, name):
        self._outputs_cache = None

    # ------------------------------------------------------------------ the block
    def _stateless(self) -> bool:
        block = self._try_block()
        return block is not None and getattr(block, "stateless", False)

    def _parameter_arrays(self) -> dict[str, np.ndarray]:
        return {p.name: p.array(self._params[p.name]) for p in self.definition.parameters}

    def _try_block(self) -> Block | None:
        if self._block is None and self._block_error is None:
            try:
                block = create_block(self.definition.kind, self._parameter_arrays(), self.definition.options,
                                     self.definition.kind_module)
                if block.feedthrough and not self.definition.feedthrough:
                    raise ParameterError("D: the parameters give a direct feedthrough but the FMU was "
                                         "built without one; rebuild it with that D")
                self._block = block
            except Exception as exc:  # a bad parameter set must not crash the host
                self._block_error = f"{type(exc).__name__}: {exc}"
                self.log(f"cannot build the block from the parameters: {self._block_error}",
                         Fmi2Status.error)
        return self._block

    def _output(self, port: str, index: int) -> float:
        if self._outputs_cache is None:
            block = self._try_block()
            if block is None:
                return float("nan")
            try:
                self._outputs_cache = block.outputs(self._time, self._inputs)
            except Exception as exc:
                self.log(f"output {port} at t={self._time:g}: {type(exc).__name__}: {exc}",
                         Fmi2Status.error)
                return float("nan")
        return float(self._outputs_cache[port][index])

    # ------------------------------------------------------------------ FMI calls
    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        self._time = float(start_time)

    def exit_initialization_mode(self):
        self._remember_inputs(self._time)
        self._stepping = True
        if self._try_block() is None:
            raise ParameterError(f"the parameters do not define a valid block: {self._block_error}")

    @property
    def last_successful_time(self) -> float:
        return self._time

    def set_real_input_derivatives(self, vrs, orders, values):
        """First time derivatives of inputs for the next step (``fmi2SetRealInputDerivatives``).

        They override the port's ``<port>_interpolation`` mode for that step
        only: ``u(t + s) = u(t) + s du``; after the step the input holds
        ``u(t) + h du`` (what direct-feedthrough outputs at ``t + h`` see).
        Higher orders are ignored with a warning.
        """
        for vr, order, value in zip(vrs, orders, values):
            if vr not in self._input_elements:
                raise ValueError(f"value reference {vr} is not a real input")
            if order != 1:
                self.log(f"input derivative of order {order} ignored (only order 1 is used)", Fmi2Status.warning)
                continue
            port, index = self._input_elements[vr]
            self._derivatives.setdefault(port, np.zeros_like(self._inputs[port]))[index] = value

    def _remember_inputs(self, time: float, step: float = 0.0):
        """Record each input with the time it belongs to, after a step of length ``step``.

        An input with a derivative for the step followed it to ``time + step``;
        an interpolated input was set as its value at ``time + step``.
        """
        for port, value in self._inputs.items():
            if port in self._derivatives:
                value += step * self._derivatives[port]
            at_end = port in self._derivatives or self._modes[port][0] == _INTERPOLATE
            self._last_inputs[port] = (value.copy(), time + step if at_end else time)
        self._derivatives.clear()

    def _segment(self, port: str, t: float, h: float) -> Segment:
        value = self._inputs[port]
        if port in self._derivatives:
            return Segment(value.copy(), self._derivatives[port].copy())
        mode = self._modes[port][0]
        previous, previous_time = self._last_inputs.get(port, (value, t))
        if mode == _INTERPOLATE:
            return Segment.between(previous, value, h)
        if mode == _EXTRAPOLATE and previous_time < t:
            return Segment(value.copy(), (value - previous) / (t - previous_time))
        return Segment.hold(value.copy())

    def do_step(self, current_time, step_size):
        try:
            block = self._try_block()
            if block is None:
                raise RuntimeError(self._block_error)
            for port, value in self._inputs.items():
                finite_signal(f"input {port}", value)
            segments = {port: self._segment(port, current_time, step_size) for port in self._inputs}
            block.advance(current_time, step_size, segments)
        except Exception as exc:
            self.log(f"do_step(t={current_time:g}, h={step_size:g}) refused: {type(exc).__name__}: {exc}",
                     Fmi2Status.discard)
            return False
        self._remember_inputs(current_time, step_size)
        self._time = current_time + step_size
        self._outputs_cache = None
        return True

    # ------------------------------------------------------------------ FMU state
    def get_fmu_state(self) -> dict:
        """A deep copy of everything that evolves: parameters, inputs, block state, history."""
        return copy.deepcopy({
            "params": self._params, "inputs": self._inputs, "modes": self._modes,
            "derivatives": self._derivatives, "last_inputs": self._last_inputs, "time": self._time,
            "stepping": self._stepping, "block_error": self._block_error,
            "block": None if self._block is None else self._block.get_state(),
        })

    def set_fmu_state(self, state: dict) -> None:
        state = copy.deepcopy(state)
        for name in ("params", "inputs", "modes"):  # the variable getters hold these arrays: copy into them
            for key, values in state[name].items():
                getattr(self, f"_{name}")[key][:] = values
        self._derivatives = state["derivatives"]
        self._last_inputs = state["last_inputs"]
        self._time = state["time"]
        self._stepping = state["stepping"]
        self._block_error = state["block_error"]
        self._block = None
        if state["block"] is not None:
            self._block_error = None
            self._try_block().set_state(state["block"])
        self._outputs_cache = None

    @staticmethod
    def serialize_fmu_state(state: dict) -> bytes:
        return pickle.dumps(state, protocol=pickle.HIGHEST_PROTOCOL)

    @staticmethod
    def deserialize_fmu_state(data: bytes) -> dict:
        """Unpickle a state made by :meth:`serialize_fmu_state`; only project and numpy types load."""
        return _StateUnpickler(io.BytesIO(data)).load()

    # ------------------------------------------------------------------ modelDescription
    def to_xml(self, model_options=None) -> Element:
        """pythonfmu's description plus units, mode ranges and a complete ModelStructure."""
        root = super().to_xml(model_options or {})
        root.find("CoSimulation").attrib.update(CAPABILITIES, canHandleVariableCommunicationStepSize=str(
            self.definition.variable_step).lower())
        self._add_units(root)
        for variable in root.iter("ScalarVariable"):
            if variable.get("name", "").endswith("_interpolation"):
                integer = variable.find("Integer")
                integer.set("min", "0")
                integer.set("max", "2")
        self._rebuild_model_structure(root)
        return root

    def _add_units(self, root: Element):
        units = sorted(set(self._units.values()))
        if not units:
            return
        definitions = Element("UnitDefinitions")
        for unit in units:
            SubElement(definitions, "Unit", {"name": unit})
        children = list(root)
        position = [i for i, c in enumerate(children) if c.tag == "CoSimulation"][0] + 1
        root.insert(position, definitions)
        for variable in root.iter("ScalarVariable"):
            unit = self._units.get(variable.get("name"))
            if unit:
                variable.find("Real").set("unit", unit)

    def _rebuild_model_structure(self, root: Element):
        structure = root.find("ModelStructure")
        for child in list(structure):
            structure.remove(child)
        variables = list(self.vars.values())
        index = {v.name: i + 1 for i, v in enumerate(variables)}
        outputs = [v for v in variables if v.causality == Fmi2Causality.output]
        inputs = [v for v in variables if v.causality == Fmi2Causality.input]
        dependencies = " ".join(str(index[v.name]) for v in inputs) if self.definition.feedthrough else ""
        if outputs:
            node = SubElement(structure, "Outputs")
            for v in outputs:
                SubElement(node, "Unknown", {"index": str(index[v.name]), "dependencies": dependencies})
            node = SubElement(structure, "InitialUnknowns")
            for v in outputs:
                SubElement(node, "Unknown", {"index": str(index[v.name])})
