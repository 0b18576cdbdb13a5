"""The one generic FMI 2.0 co-simulation slave: any block becomes an FMU.

Every FMU of the project contains a two-line module::

    from fmus.runtime.slave import BlockSlave
    class ship_observer(BlockSlave):
        definition_file = "ship_observer.json"

and the definition file (:mod:`fmus.runtime.definition`).  This class turns the
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

Faults never crash the host and never corrupt the instance (``docs/faults.md`` has the table):

* a call the slave cannot carry out without harm is *refused*: it raises :class:`Refused`
  (fmi2Error through the native binary) before changing anything, so the instance stays exactly
  as it was and in its FMI state -- a bad value reference or type, setting an output, a fixed
  parameter after initialization, an interpolation mode other than 0, 1, 2, a parameter set
  that does not define a valid block or gives non-finite (or huge) first outputs at
  ``exit_initialization_mode`` (naming the parameters), outputs that cannot be computed, FMU
  states of another FMU or version, damaged or forged bytes;
* every step either succeeds with a finite state or changes nothing: NaN/inf/huge inputs and
  input derivatives, a step longer than the block's sub-step budget, a failure inside the
  block, or a new state or outputs that are not finite or beyond the block's
  ``magnitude_bound`` -- the step is rolled back, one line naming the input or parameter at
  fault is logged at Discard level and ``do_step`` returns False (fmi2Discard);
* anything else -- an unexpected exception, a bug inside a block (logged at Error level, "a bug:
  please report") -- is a *failure*: fmi2Error, and the binary puts the instance in the FMI error
  state (fmi2SetFMUstate, fmi2Reset or fmi2FreeInstance go on);
* FMU states are plain data (:mod:`observers.state`) in an explicit, versioned, checksummed
  format (:mod:`fmus.runtime.state_format`), the binary's own fields (FMI version, state machine state)
  included: the one serialized form of an FMU state.
"""

from __future__ import annotations

import contextvars
import functools
import math
from enum import IntEnum
from pathlib import Path
from typing import ClassVar
from xml.etree.ElementTree import Element, ParseError, SubElement, iterparse

import numpy as np
from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real, String
from pythonfmu.enums import Fmi2Status
from pythonfmu.default_experiment import DefaultExperiment

from observers.block import MAGNITUDE_BOUND, Block, Segment
from observers.checks import ParameterError
from observers.state import Leaves, StateError, capture, out_of_bounds, plain, within, within_bound

from ..definition import FmuDefinition, element_unit
from ..kinds import create_block
from ..state_format import StateFormatError, pack, unpack

__all__ = ["BlockSlave", "InputMode", "FmuState", "Refused", "CAPABILITIES"]


class Refused(Exception):
    """The slave refused an FMI call after checking it, and changed nothing (fmi2Error; the native
    binary keeps the instance in its FMI state: the next legal call works).  Any other exception
    of an FMI call is a failure (the binary's FMI error state)."""


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


#: exceptions of a step that are faults of the data (fmi2Discard); anything else is a bug (fmi2Error)
_NUMERICAL_FAULTS = (ValueError, ArithmeticError, np.linalg.LinAlgError)


def _quiet_numerics():
    """numpy's floating-point errors ignored inside the block's computations, whatever the host set.

    The FMU shares numpy with its importer: a host that called ``np.seterr(all="raise")`` (or turned
    warnings into errors) would otherwise make a harmless underflow inside a block an exception and
    the step a failure.  Overflow and invalid results need no warning either: the slave checks every
    new state and output for finiteness and bounds itself (docs/faults.md).  ``np.errstate`` is
    context-local, so the host's own settings are untouched.  Cost: ~0.8 us per use.
    """
    return np.errstate(all="ignore")


def _numerics_context() -> contextvars.Context | None:
    """A context of its own in which numpy ignores floating-point errors (what :func:`_quiet_numerics`
    sets), for an instance to run its entry points in at ~0.03 us a call instead of ~0.8 us; None
    where numpy keeps that setting per thread rather than per context (numpy < 2), since setting it
    would then change the host's."""
    if not _ERRORS_PER_CONTEXT:
        return None
    context = contextvars.Context()
    context.run(np.seterr, all="ignore")
    return context


def _errors_per_context() -> bool:
    """True if numpy's error setting lives in a context variable (numpy >= 2): set in a context of its
    own, it leaves the caller's unchanged (checked, and put back if not)."""
    before = np.geterr()
    contextvars.Context().run(np.seterr, all="ignore")
    if np.geterr() == before:
        return True
    np.seterr(**before)
    return False


_ERRORS_PER_CONTEXT = _errors_per_context()


def _host_independent_numerics(method):
    """``method`` (an FMI entry point that runs block code) with numpy's floating-point errors ignored
    (:func:`_quiet_numerics`): run in the instance's own context (:func:`_numerics_context`), or under
    ``np.errstate`` where there is none.  Entry points do not call each other (a context cannot be
    entered twice): they share undecorated methods instead."""
    @functools.wraps(method)
    def quiet(self, *args):
        context = self._numerics
        if context is None:
            with _quiet_numerics():
                return method(self, *args)
        return context.run(method, self, *args)
    return quiet


class FmuState:
    """An FMU state (``fmi2GetFMUstate``): plain data, tagged with the FMU it belongs to."""

    __slots__ = ("identity", "tree")

    def __init__(self, identity: str, tree: dict):
        self.identity, self.tree = identity, tree


#: the sections of an FMU state's tree (``loader``: the native binary's fields, see get_fmu_state)
_SECTIONS = {"time", "params", "inputs", "modes", "derivatives", "last_inputs", "block_error", "block", "initialized",
             "loader"}


@functools.lru_cache(maxsize=None)
def _guid(model_description: str) -> str:
    """The token of the FMU unpacked around ``resources``: its GUID (FMI 2.0) or instantiationToken
    (FMI 3.0); "" when not run from an FMU."""
    try:
        for _, element in iterparse(model_description, events=("start",)):
            return element.get("guid") or element.get("instantiationToken") or ""
    except (OSError, ParseError):
        pass
    return ""


def _verdict(value, bound: float) -> str:
    """``"nan is not finite"``, ``"1e+308 exceeds the bound 1e+100"`` (the worst entry of an array)."""
    where = ""
    if isinstance(value, np.ndarray):
        flat = value.ravel()
        if flat.size > 1:
            where = f" (entry {int(np.argmax(np.where(np.isfinite(flat), np.abs(flat), np.inf))) + 1} of {flat.size})"
            value = flat[int(np.argmax(np.where(np.isfinite(flat), np.abs(flat), np.inf)))]
        else:
            value = flat[0] if flat.size else 0.0
    value = complex(value) if np.iscomplexobj(value) else float(value)
    if not np.isfinite(value):
        return f"{value:g}{where} is not finite"
    return f"{value:g}{where} exceeds the bound {bound:g} in magnitude"


def interpolation_parameter(port: str) -> str:
    return f"{port}_interpolation"


def _slices(ports) -> dict[str, slice]:
    """Each port's elements in the vector of all ports' elements in declaration order."""
    where, offset = {}, 0
    for port in ports:
        where[port.name] = slice(offset, offset + port.size)
        offset += port.size
    return where


class _BatchPlan:
    """What :meth:`BlockSlave.step_batched` exchanges with the native binary: the value references of
    one call, and the vectors whose memory the binary fills (``values``, ``slopes``) before the call and
    reads (``outputs``) after it; where they go among the FMU's inputs and outputs."""

    __slots__ = ("input_vrs", "output_vrs", "given_data", "values", "slopes", "outputs", "derivatives", "positions",
                 "given", "held", "common", "in_order", "output_order")

    def __init__(self, input_vrs, derivatives, output_vrs, positions: list[int], input_slices: dict[str, slice],
                 output_positions: list[int], output_count: int):
        self.input_vrs, self.output_vrs, self.derivatives = list(input_vrs), list(output_vrs), bool(derivatives)
        self.given_data = np.zeros(2 * len(input_vrs))           # values, then slopes: one test of both
        self.values, self.slopes = self.given_data[:len(input_vrs)], self.given_data[len(input_vrs):]
        self.outputs = np.zeros(len(output_vrs))
        self.positions = np.array(positions, dtype=np.intp)      # each value's place in the flat inputs
        given = set(positions)
        covered = {port: sum(i in given for i in range(where.start, where.stop)) for port, where in input_slices.items()}
        size = sum(where.stop - where.start for where in input_slices.values())
        self.in_order = list(positions) == list(range(size))     # every input, in declaration order
        # ports set by the call and where they are in its vectors (None: the only port, the whole vectors)
        self.given = tuple((port, None if self.in_order and len(input_slices) == 1 else input_slices[port])
                           for port, n in covered.items() if n)
        self.held = [port for port, n in covered.items() if not n]                     # ports left as they are
        # the plan's part of a common step: slopes given, every port given whole or not at all
        self.common = self.derivatives and \
            all(covered[port] in (0, where.stop - where.start) for port, where in input_slices.items())
        # positions in the flat outputs; None: all of them in declaration order (nothing to permute)
        self.output_order = None if list(output_positions) == list(range(output_count)) else \
            np.array(output_positions, dtype=np.intp)


class BlockSlave(Fmi2Slave):
    """Generic adapter from a :class:`~observers.block.Block` to ``pythonfmu``."""

    definition_file: ClassVar[str] = ""
    author = "obsfmu"
    license = "MIT"
    #: the exception of refused calls, found here by the native binary's bridge
    Refused: ClassVar[type] = Refused
    #: the binary's test of numbers, set on each instance by the bridge (fmus/native/bridge.c, ``native_within``):
    #: ``within`` and ``within_bound`` of observers.state in one C call, without concatenating; None in process
    native_within: ClassVar = None

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        definition = FmuDefinition.load(Path(self.resources) / self.definition_file)
        self.definition = definition
        self.modelName = definition.model_name
        self.description = definition.description
        if definition.default_experiment:
            self.default_experiment = DefaultExperiment(**definition.default_experiment)

        self._params = {p.name: np.array(p.value, dtype=float) for p in definition.parameters}
        self._input_slices = _slices(definition.inputs)     # port -> its elements in the flat input vector
        self._output_slices = _slices(definition.outputs)
        self._input_flat = np.zeros(sum(p.size for p in definition.inputs))
        self._inputs = {port: self._input_flat[where] for port, where in self._input_slices.items()}   # views
        self._modes = {p.name: np.zeros(1, dtype=int) for p in definition.inputs}
        self._units: dict[str, str] = {}
        self._block: Block | None = None
        self._block_error: str | None = None
        self._outputs_cache: dict[str, np.ndarray] | None = None
        self._time = 0.0
        self._stepping = False
        self._bound = MAGNITUDE_BOUND                    # the block's magnitude_bound once it exists
        self._numerics = _numerics_context()             # where entry points run (numpy errors ignored)
        self._feedthrough = True                         # the block's, once it exists
        self._bad: dict[str, float] = {}                 # input (or der(input)) element -> refused value
        self._snapshot: tuple[dict, Leaves] | None = None   # the block's state now, checked (rollback point)
        self._last_inputs = {}                          # port -> (its value, the time it belongs to)
        self._derivatives: dict[str, np.ndarray] = {}  # first input derivatives for the next step
        self._derivative_store = {p.name: np.zeros(p.size) for p in definition.inputs}  # reused (one per port)
        self._batch: _BatchPlan | None = None          # the buffers of step_batched (native binary)
        self._input_elements: dict[int, tuple[str, int, str]] = {}  # value reference -> (port, index, name)
        self._element_names = {p.name: p.element_names for p in definition.inputs}
        self._output_offsets: dict[int, int] = {}    # output value reference -> position in the flat outputs
        self._output_plans: dict[tuple, np.ndarray | None] = {}   # fmi2GetReal's vrs -> positions (None: not all outputs)
        self._flat: tuple[dict | None, np.ndarray] = (None, np.zeros(0))   # (outputs cache, its flat vector)

        for p in definition.parameters:
            self._register_array(p.element_names, self._params[p.name], Fmi2Causality.parameter,
                                 p.description, p.unit, on_set=self._parameters_changed)
        if not self._stateless():
            for port in definition.inputs:
                self._register_mode(port.name)
        for port in definition.inputs:
            references = self._register_array(port.element_names, self._inputs[port.name], Fmi2Causality.input,
                                              port.description, port.unit, on_set=self._input_changed)
            self._input_elements.update({vr: (port.name, i, name)
                                         for i, (vr, name) in enumerate(zip(references, port.element_names))})
        for port in definition.outputs:
            self._register_outputs(port)

    # ------------------------------------------------------------------ variables
    def _register_array(self, names, store: np.ndarray, causality, description, unit, on_set) -> list[int]:
        variability = Fmi2Variability.fixed if causality == Fmi2Causality.parameter else Fmi2Variability.continuous
        references = []
        for i, name in enumerate(names):
            def setter(value, i=i, name=name):
                store[i] = value
                on_set(name, value)
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
            store[0] = int(value)          # set_integer checked the value first

        self.register_variable(Integer(
            interpolation_parameter(port), causality=Fmi2Causality.parameter,
            variability=Fmi2Variability.fixed,
            description=f"input {port} inside a step: 0 hold, 1 extrapolate from the previous point "
                        f"(value at step start), 2 interpolate (value at step end, Gauss-Seidel)",
            getter=lambda: int(store[0]), setter=setter))

    def _register_outputs(self, port):
        for i, name in enumerate(port.element_names):
            variable = Real(name, causality=Fmi2Causality.output, variability=Fmi2Variability.continuous,
                            description=port.description, getter=lambda p=port.name, i=i: self._output(p, i))
            self.register_variable(variable)
            self._output_offsets[variable.value_reference] = len(self._output_offsets)
            if element_unit(port.unit, i):
                self._units[name] = element_unit(port.unit, i)

    def _parameters_changed(self, name, value):
        self._block = None
        self._block_error = None
        self._outputs_cache = None
        self._snapshot = None

    def _input_changed(self, name, value):
        self._flag(name, value)
        if self._feedthrough:                  # other blocks' outputs do not depend on the inputs
            self._outputs_cache = None

    def _flag(self, name: str, value: float) -> None:
        """Remember an input (or input derivative) element that a step must refuse."""
        if -self._bound <= value <= self._bound:
            self._bad.pop(name, None)
        else:
            self._bad[name] = value

    def _variable(self, vr, kind):
        """The variable of ``vr``, of type ``kind``; :class:`Refused` otherwise."""
        variable = self.vars.get(vr)
        if variable is None:
            raise Refused(f"value reference {vr} does not exist")
        if not isinstance(variable, kind):
            raise Refused(f"{variable.name} (value reference {vr}) is not a {kind.__name__} variable")
        return variable

    def _check_writable(self, vrs, kind, values) -> None:
        """Refuse a whole ``fmi2Set*`` call before any value is set (:class:`Refused`)."""
        fixed = []
        for vr, value in zip(vrs, values):
            variable = self._variable(vr, kind)
            if variable.setter is None or variable.causality == Fmi2Causality.output:
                raise Refused(f"{variable.name} is an output; outputs cannot be set")
            if variable.causality == Fmi2Causality.parameter:
                if self._stepping:
                    fixed.append(f"{variable.name} (in use: {variable.getter():g})")
                elif kind is Integer and int(value) not in InputMode._value2member_map_:
                    raise Refused(f"{variable.name}: {value} is not 0 (hold), 1 (extrapolate) or "
                                  f"2 (interpolate); keeping {variable.getter()}")
        if fixed:
            raise Refused(f"{', '.join(fixed)}: parameters are fixed after initialization "
                          f"(fmi2ExitInitializationMode) and keep their values; set them before, "
                          f"or reset the instance")

    def _read(self, read, kind, vrs) -> list:
        """pythonfmu's getter ``read`` of ``vrs``; a value reference that does not exist or is not a
        ``kind`` variable is refused (:class:`Refused`), any other exception is a bug."""
        try:
            return read(self, vrs)
        except (KeyError, TypeError):
            for vr in vrs:
                self._variable(vr, kind)
            raise

    def set_real(self, vrs, values):
        elements = self._input_elements
        targets = [elements.get(vr) for vr in vrs]
        if None in targets:
            self._check_writable(vrs, Real, values)
            super().set_real(vrs, values)
            return
        inputs, bound, bad = self._inputs, self._bound, self._bad   # the hot path: inputs, every step
        for (port, index, name), value in zip(targets, values):
            inputs[port][index] = value
            if -bound <= value <= bound:
                if bad:
                    bad.pop(name, None)
            else:
                bad[name] = value
        if self._feedthrough:                  # other blocks' outputs do not depend on the inputs
            self._outputs_cache = None

    def set_integer(self, vrs, values):
        self._check_writable(vrs, Integer, values)
        super().set_integer(vrs, values)

    def set_boolean(self, vrs, values):
        self._check_writable(vrs, Boolean, values)
        super().set_boolean(vrs, values)

    def set_string(self, vrs, values):
        self._check_writable(vrs, String, values)
        super().set_string(vrs, values)

    def get_real(self, vrs):
        """``fmi2GetReal``: outputs only (every step) from one flat vector of the cached outputs;
        anything else variable by variable through pythonfmu's getters."""
        key = tuple(vrs)
        positions = self._output_plans.get(key, False)
        if positions is False:
            offsets = self._output_offsets
            positions = np.array([offsets[vr] for vr in key], dtype=np.intp) \
                if key and all(vr in offsets for vr in key) else None
            if len(self._output_plans) < 64:
                self._output_plans[key] = positions
        flat = None if positions is None else self._flat_outputs()
        if flat is None or flat.size != len(self._output_offsets):   # (a block with a wrong output size)
            return self._read(Fmi2Slave.get_real, Real, vrs)
        return flat[positions].tolist()

    def _flat_outputs(self) -> np.ndarray:
        """Every output element in declaration order, as one vector (rebuilt when the outputs change)."""
        cache = self._outputs_cache
        if cache is None:
            first = self.definition.outputs[0]
            self._output(first.name, 0)          # computes the outputs, or refuses naming why
            cache = self._outputs_cache
        source, flat = self._flat
        if source is not cache:
            flat = np.concatenate([np.asarray(cache[p.name], dtype=float).ravel() for p in self.definition.outputs])
            self._flat = cache, flat
        return flat

    def get_integer(self, vrs):
        return self._read(Fmi2Slave.get_integer, Integer, vrs)

    def get_boolean(self, vrs):
        return self._read(Fmi2Slave.get_boolean, Boolean, vrs)

    def get_string(self, vrs):
        return self._read(Fmi2Slave.get_string, String, vrs)

    # ------------------------------------------------------------------ the block
    def _stateless(self) -> bool:
        block = self._try_block()
        return block is not None and getattr(block, "stateless", False)

    def _parameter_arrays(self) -> dict[str, np.ndarray]:
        return {p.name: p.array(self._params[p.name]) for p in self.definition.parameters}

    def _parameter_fault(self, params: dict[str, np.ndarray]) -> str | None:
        """NaN, inf or huge parameter values, named (before anything is built from them)."""
        bad = [f"{name} = {value:g}" for p in self.definition.parameters
               for name, value in zip(p.element_names, params[p.name]) if not abs(value) <= MAGNITUDE_BOUND]
        if bad:
            more = f" (and {len(bad) - 5} more)" if len(bad) > 5 else ""
            return (f"{', '.join(bad[:5])}{more}: parameters must be finite and at most "
                    f"{MAGNITUDE_BOUND:g} in magnitude")
        return None

    def _new_block(self, params: dict[str, np.ndarray]) -> Block:
        """The block of the parameter store ``params``; raises naming the parameter at fault."""
        fault = self._parameter_fault(params)
        if fault:
            raise ParameterError(fault)
        block = create_block(self.definition.kind, {p.name: p.array(params[p.name]) for p in self.definition.parameters},
                             self.definition.options, self.definition.kind_module)
        if block.feedthrough and not self.definition.feedthrough:
            raise ParameterError("D: the parameters give a direct feedthrough but the FMU was "
                                 "built without one; rebuild it with that D")
        return block

    def _try_block(self) -> Block | None:
        """The block of the parameters, built once; None (the reason in ``_block_error``) if they define none."""
        if self._block is None and self._block_error is None:
            try:
                with _quiet_numerics():
                    self._use_block(self._new_block(self._params))
            except Exception as exc:  # a bad parameter set must not crash the host; callers report it
                self._block_error = f"{type(exc).__name__}: {exc}"
        return self._block

    def _use_block(self, block: Block | None) -> None:
        self._block, self._snapshot, self._outputs_cache = block, None, None
        if block is not None:
            block.caller_rolls_back = True       # _checked_step restores the state of a failed step
        self._bound = MAGNITUDE_BOUND if block is None else block.magnitude_bound
        self._feedthrough = block is None or block.feedthrough
        self._bad = {}
        for port, names in self._element_names.items():
            for name, value in zip(names, self._inputs[port]):
                self._flag(name, value)
            for name, value in zip(names, self._derivatives.get(port, ())):
                self._flag(f"der({name})", value)

    def _output(self, port: str, index: int) -> float:
        if self._outputs_cache is None:
            block = self._try_block()
            if block is None:
                raise Refused(f"output {port} cannot be computed: the parameters do not define a valid block: "
                              f"{self._block_error}")
            try:
                with _quiet_numerics():
                    self._outputs_cache = block.outputs(self._time, self._inputs)
            except _NUMERICAL_FAULTS as exc:       # anything else is a bug: a failure
                raise Refused(f"output {port} at t={self._time:g} cannot be computed: "
                              f"{type(exc).__name__}: {exc}") from None
        return float(self._outputs_cache[port][index])

    def _output_fault(self, outputs: dict[str, np.ndarray], bound: float) -> str | None:
        """The first output element that is not finite or beyond ``bound``."""
        for port, values in outputs.items():
            values = np.asarray(values, dtype=float)
            if not within(values, bound):
                names = next(p.element_names for p in self.definition.outputs if p.name == port)
                i = int(np.argmax(np.where(np.isfinite(values), np.abs(values), np.inf)))
                return f"output {names[i]} = {_verdict(values[i], bound)}"
        return None

    @staticmethod
    def _state_fault(tree: dict, leaves: Leaves | None, previous: Leaves | None, bound: float) -> str | None:
        """The first state value that is not finite or beyond ``bound``: tested in one vector of ``leaves``
        (arrays of ``previous`` skipped), walked only if that fails; ``leaves`` None: walked (a restored
        state, whose immutable objects are plain data when it came as bytes)."""
        if leaves is not None and within_bound(leaves, bound, previous):
            return None
        found = out_of_bounds(tree, bound)
        if found is None and leaves is None:
            return None
        path, value = found or ("state", float("nan"))
        return f"state {path} = {_verdict(value, bound)}"

    def _suspects(self) -> str:
        """Inputs and the parameters changed from their start values: what to look at."""
        inputs = [f"{name} = {value:g}" for port, names in self._element_names.items()
                  for name, value in zip(names, self._inputs[port])]
        inputs += [f"der({name}) = {value:g}" for port, derivative in self._derivatives.items()
                   for name, value in zip(self._element_names[port], derivative)]
        changed = [f"{name} = {value:g}" for p in self.definition.parameters
                   for name, value, start in zip(p.element_names, self._params[p.name], p.value) if value != start]
        text = f"inputs {', '.join(inputs[:6])}{' ...' if len(inputs) > 6 else ''}; " if inputs else ""
        if changed:
            return text + f"parameters changed from their start values: {', '.join(changed[:6])}" + \
                (" ..." if len(changed) > 6 else "")
        return text + "all parameters at their start values"

    # ------------------------------------------------------------------ FMI calls
    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        if not math.isfinite(start_time):
            raise Refused(f"start time {start_time} is not finite")
        self._time = float(start_time)

    @_host_independent_numerics
    def exit_initialization_mode(self):
        """Start stepping with the block of the parameters; :class:`Refused` (naming the parameters,
        nothing changed: still in initialization mode) when they define no valid block or its first
        outputs are not finite or beyond its ``magnitude_bound``."""
        block = self._block
        if block is None:
            try:
                block = self._new_block(self._params)
            except Exception as exc:  # nothing changed: a refusal, whatever the block raised
                raise Refused(f"the parameters do not define a valid block: {type(exc).__name__}: {exc}") from None
        bound, outputs = block.magnitude_bound, None
        if all(within(value, bound) for value in self._inputs.values()):  # else the first step names them
            try:
                outputs = block.outputs(self._time, self._inputs)
                fault = self._output_fault(outputs, bound)
            except _NUMERICAL_FAULTS as exc:
                fault = f"computing them raised {type(exc).__name__}: {exc}"
            if fault:
                raise Refused(f"the first outputs are not usable: {fault} ({self._suspects()})")
        # nothing can fail from here on
        if block is not self._block:
            self._use_block(block)
        self._remember_inputs(self._time)
        self._stepping = True
        if outputs is not None:
            self._outputs_cache = outputs

    @property
    def last_successful_time(self) -> float:
        return self._time

    def set_real_input_derivatives(self, vrs, orders, values):
        """First time derivatives of inputs for the next step (``fmi2SetRealInputDerivatives``).

        They override the port's ``<port>_interpolation`` mode for that step
        only: ``u(t + s) = u(t) + s du``; after the step the input holds
        ``u(t) + h du`` (what direct-feedthrough outputs at ``t + h`` see).
        Higher orders are ignored with a warning.  NaN, inf and huge values make the next
        step refuse (like inputs).
        """
        elements, derivatives = self._input_elements, self._derivatives
        unknown = [vr for vr in vrs if vr not in elements]
        if unknown:
            raise Refused(f"value reference {unknown[0]} is not a real input")
        for vr, order, value in zip(vrs, orders, values):
            if order != 1:
                self.log(f"input derivative of order {order} ignored (only order 1 is used)", Fmi2Status.warning)
                continue
            port, index, name = elements[vr]
            if port not in derivatives:
                store = derivatives[port] = self._derivative_store[port]   # no allocation per step
                store[:] = 0.0
            derivatives[port][index] = value
            if not -self._bound <= value <= self._bound or self._bad:
                self._flag(f"der({name})", value)

    def clear_input_derivatives(self, vrs) -> None:
        """Forget the input derivatives of the ports of ``vrs`` (the FMI 3.0 binary: the slopes it gave a
        step from the intermediate update belong to that step; a discarded step gives them back)."""
        for vr in vrs:
            port, _, _ = self._input_elements[vr]
            if self._derivatives.pop(port, None) is not None:
                for name in self._element_names[port]:
                    self._bad.pop(f"der({name})", None)

    @property
    def _last_inputs(self) -> dict[str, tuple[np.ndarray, float]]:
        """Each input's last recorded value and the time it belongs to (:meth:`_remember_inputs`)."""
        if self._pending_record is not None:    # a batched step's (step_batched): as _remember_inputs records
            plan, start, end, time, end_time, at_end = self._pending_record
            self._pending_record, slices = None, self._input_slices
            self._recorded = {port: (end[where], end_time) for port, where in slices.items()}
            for port in plan.held:
                self._recorded[port] = (start[slices[port]], end_time if port in at_end else time)
        return self._recorded

    @_last_inputs.setter
    def _last_inputs(self, record: dict[str, tuple[np.ndarray, float]]) -> None:
        self._pending_record, self._recorded = None, record

    def _remember_inputs(self, time: float, step: float = 0.0, ends: dict[str, np.ndarray] | None = None):
        """Record each input with the time it belongs to, after a step of length ``step``.

        An input with a derivative for the step followed it to ``time + step`` (its value there,
        ``ends[port]``, a new array nobody writes into, is kept as it is); an interpolated input was
        set as its value at ``time + step``.
        """
        last, derivatives, end_time = self._last_inputs, self._derivatives, time + step
        for port, value in self._inputs.items():
            end = ends.get(port) if ends else None
            if end is not None:                  # ends: inputs with a derivative
                value[:] = end
                last[port] = (end, end_time)
            else:
                at_end = port in derivatives or self._modes[port][0] == _INTERPOLATE
                last[port] = (value.copy(), end_time if at_end else time)
        derivatives.clear()
        if self._bad:
            self._bad = {name: value for name, value in self._bad.items() if not name.startswith("der(")}

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

    def _refuse(self, t: float, h: float, reason: str, status=Fmi2Status.discard) -> bool:
        self.log(f"do_step(t={t:g}, h={h:g}) refused, state unchanged: {reason}", status)
        return False

    @_host_independent_numerics
    def do_step(self, current_time, step_size):
        return self._do_step(current_time, step_size)

    def _do_step(self, current_time, step_size) -> bool:
        t, h, block = current_time, step_size, self._block
        if block is None or self._bad or not (0.0 < h < math.inf and math.isfinite(t)):
            return self._refuse_before(t, h)
        inputs = self._inputs
        ends = {port: inputs[port] + h * slope for port, slope in self._derivatives.items()}
        segments = None if block.stateless else {port: self._segment(port, t, h) for port in inputs}
        if not self._checked_step(t, h, block, segments, ends):
            return False
        self._remember_inputs(t, h, ends)
        return True

    def _checked_step(self, t: float, h: float, block: Block, segments: dict | None, ends: dict,
                      plan: _BatchPlan | None = None) -> bool:
        """Advance ``block`` over the input ``segments`` (None: a stateless block) and compute its outputs
        with the inputs at the step end (``ends``: those that moved); keep the result only if the new
        state, the inputs at the end and the outputs are all finite and within the bound, else roll back
        and refuse (docs/faults.md).  True if the step was taken (the caller then remembers the inputs).

        With ``plan`` (:meth:`step_batched`, every output in declaration order, the inputs at the end
        bounded by construction) the outputs are written into ``plan.outputs`` and tested there as one
        vector; the binary copies that vector out only when the step is taken."""
        inputs, bound = self._inputs, self._bound
        at_end = {**inputs, **ends} if ends else inputs
        # the state now (checked, with its leaves, or captured now) to roll back to; None: a stateless block
        before = None if block.stateless else self._snapshot or (capture(block, rollback=True), None)
        checked = before and before[1]
        tree = leaves = outputs = None
        try:
            if before is not None:
                block.advance(t, h, segments)
                leaves = Leaves()
                tree = capture(block, leaves, rollback=True)
            outputs = block.outputs(t + h, at_end)
            if plan is None:
                tested = within_bound(leaves, bound, checked, [*ends.values(), *outputs.values()])
            else:
                self._write_outputs(plan, outputs)
                native = self.native_within       # the binary's test: its True decides, numpy decides the rest
                state = (None, None, None) if leaves is None else (leaves.arrays, checked and checked.arrays,
                                                                   leaves.floats)
                tested = (native is not None and native(bound, plan.outputs, *state) is True) \
                    or (within(plan.outputs, bound) and within_bound(leaves, bound, checked))
            fault = None if tested else self._fault(tree, leaves, checked, ends, outputs, None)
        except BaseException as exc:            # KeyboardInterrupt too: roll back, then let it through
            if before is not None:
                block.set_state(before[0], check=False)
            if not isinstance(exc, Exception):
                raise
            if isinstance(exc, _NUMERICAL_FAULTS) and not isinstance(exc, StateError):
                return self._refuse(t, h, self._fault(tree, leaves, checked, ends, outputs, exc))
            return self._refuse(t, h, f"{type(exc).__name__}: {exc} (a bug: please report)", Fmi2Status.error)
        if fault:
            if before is not None:
                block.set_state(before[0], check=False)
            return self._refuse(t, h, fault)
        self._time = t + h
        self._snapshot = None if tree is None else (tree, leaves)
        self._outputs_cache = outputs
        return True

    # ------------------------------------------------------------------ one call per step (native binary)
    def batch_plan(self, input_vrs, derivatives, output_vrs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Prepare :meth:`step_batched` for these value references: the vectors of input values, input
        slopes (used if ``derivatives``) and outputs that the native binary fills and reads.

        :class:`Refused` names a value reference that is not a real input (or is given twice) or not
        an output.
        """
        positions, offsets = [], self._output_offsets
        flat_of = {vr: self._input_slices[port].start + index for vr, (port, index, _) in self._input_elements.items()}
        for vr in input_vrs:
            if vr not in flat_of:
                raise Refused(f"value reference {vr} is not a real input")
            positions.append(flat_of[vr])
        if len(set(positions)) != len(positions):
            raise Refused("a value reference is given twice among the inputs of one step")
        unknown = [vr for vr in output_vrs if vr not in offsets]
        if unknown:
            raise Refused(f"value reference {unknown[0]} is not an output")
        plan = _BatchPlan(input_vrs, derivatives, output_vrs, positions, self._input_slices,
                          [offsets[vr] for vr in output_vrs], len(offsets))
        self._batch = plan
        return plan.values, plan.slopes, plan.outputs

    @_host_independent_numerics
    def step_batched(self, current_time, step_size) -> bool:
        """One communication step in one call, for the native binary's ``obsfmuDoStepBatched``: exactly
        ``set_real`` of the plan's inputs (:meth:`batch_plan`), ``set_real_input_derivatives`` of their
        slopes if the plan has them, ``do_step`` and ``get_real`` of the plan's outputs into its
        ``outputs`` vector -- with the same refusals, faults and results, the checks of a common step
        (every input of the FMU with a slope, all finite and within the bound) done on whole vectors.

        True: the step was taken and the outputs written; False: the step was refused (fmi2Discard),
        nothing changed but the inputs; an exception: no step was taken.
        """
        plan, block, t, h = self._batch, self._block, current_time, step_size
        data = plan.given_data
        # |value + h slope| <= (1 + h) |(value, slope)|: a common step's inputs at the end are within the bound
        if not (plan.common and block is not None and not self._bad and 0.0 < h < math.inf and math.isfinite(t)
                and data.dot(data) * (1.0 + h) ** 2 <= self._bound * self._bound):      # False if NaN
            return self._step_by_calls(plan, t, h)
        if self._feedthrough:
            self._outputs_cache = None
        flat = self._input_flat
        derivatives, ends, segments = {}, {}, {}
        if plan.given:
            values, slopes = plan.values, plan.slopes
            if plan.in_order:                                 # every input, in order: whole vectors
                flat[:] = values
                start, slope = values.copy(), slopes.copy()   # new vectors: the block may keep views of them
            else:
                flat[plan.positions] = values
                start, slope = flat.copy(), np.zeros(flat.size)
                slope[plan.positions] = slopes
            end = slope * h
            end += start
            for port, where in plan.given:
                if where is None:
                    derivatives[port], ends[port], segments[port] = slope, end, Segment(start, slope)
                else:
                    derivatives[port], ends[port] = slope[where], end[where]
                    segments[port] = Segment(start[where], derivatives[port])
        self._derivatives = derivatives
        if block.stateless:
            segments = None
        else:
            for port in plan.held:
                segments[port] = self._segment(port, t, h)
        staged = plan if plan.output_order is None else None
        if not self._checked_step(t, h, block, segments, ends, staged):
            return False
        if plan.given:     # the inputs at the end (the held ones as they were): one vector, split if read
            if plan.in_order:
                flat[:] = end
            else:
                flat[plan.positions] = end[plan.positions]
            at_end = tuple(port for port in plan.held if self._modes[port][0] == _INTERPOLATE)
            self._pending_record, self._derivatives = (plan, start, end, t, t + h, at_end), {}
        else:
            self._remember_inputs(t, h, ends)
        if staged is None:
            self._write_outputs(plan, self._outputs_cache)
        return True

    def _step_by_calls(self, plan: _BatchPlan, t: float, h: float) -> bool:
        """:meth:`step_batched` as the separate calls it stands for (what names a fault, and the rare cases)."""
        self.set_real(plan.input_vrs, plan.values.tolist())
        if plan.derivatives and plan.input_vrs:
            self.set_real_input_derivatives(plan.input_vrs, [1] * len(plan.input_vrs), plan.slopes.tolist())
        if not self._do_step(t, h):
            return False
        self._write_outputs(plan, self._outputs_cache)
        return True

    def _write_outputs(self, plan: _BatchPlan, outputs: dict) -> None:
        """The block's ``outputs`` after a step into the plan's ``outputs`` vector (in the checked step, before
        its test, for a batched step: the binary copies the vector out only for a step taken).  This cannot
        fail a step: a wrong-sized block output is logged as the bug it is."""
        try:
            if plan.output_order is None:                     # all outputs in order: port by port
                vector = plan.outputs
                for port, where in self._output_slices.items():
                    vector[where] = outputs[port]
            else:
                plan.outputs[:] = self._flat_outputs()[plan.output_order]
        except (ValueError, IndexError, KeyError) as exc:
            self.log(f"outputs after the step cannot be read: {exc} (a bug: please report)", Fmi2Status.error)

    def _refuse_before(self, t: float, h: float) -> bool:
        """A step refused before anything is computed: no block, a bad step size, a bad input."""
        if self._try_block() is None:
            return self._refuse(t, h, f"the parameters do not define a valid block: {self._block_error}",
                                Fmi2Status.error)
        if not (0.0 < h < math.inf and math.isfinite(t)):
            return self._refuse(t, h, "the step size must be positive and finite and the time finite",
                                Fmi2Status.error)
        if self._bad:
            name, value = next(iter(self._bad.items()))
            kind = "input derivative" if name.startswith("der(") else "input"
            return self._refuse(t, h, f"{kind} {name} = {_verdict(value, self._bound)}")
        return self._do_step(t, h)                # the block was built just now

    def _fault(self, tree, leaves, checked, ends, outputs, error) -> str:
        """What the test of :meth:`_checked_step` (or ``error``, raised by the step) found wrong, in words."""
        for port, end in ends.items():
            if not within(end, self._bound):
                return f"input {port} at the step end (value + h * derivative) = {_verdict(end, self._bound)}"
        if tree is not None:
            fault = self._state_fault(tree, leaves, checked, self._bound)
            if fault:
                return f"after the step {fault} ({self._suspects()})"
        if error is not None:
            return f"{type(error).__name__}: {error}"
        fault = self._output_fault(outputs, self._bound) or "a value out of bounds"
        return f"after the step {fault} ({self._suspects()})"

    # ------------------------------------------------------------------ FMU state
    @property
    def identity(self) -> str:
        """``"<model name> <GUID or instantiationToken>"``: the FMU a state belongs to."""
        guid = _guid(str(Path(self.resources).parent / "modelDescription.xml"))
        return f"{self.definition.model_name} {guid}"

    def _own(self, state) -> FmuState:
        """``state`` if it is a state of this FMU; :class:`Refused` otherwise."""
        if not isinstance(state, FmuState):
            raise Refused(f"not an FMU state of {self.definition.model_name} (a {type(state).__name__})")
        if state.identity != self.identity:
            raise Refused(f"this state belongs to another FMU ({state.identity!r}), not to {self.identity!r}")
        return state

    def get_fmu_state(self, loader: dict | None = None) -> FmuState:
        """Everything that evolves, as plain data: time, parameters, inputs, block state, history,
        whether initialization is over, and ``loader``: the native binary's own fields (its FMI
        version and state machine state, ``{"fmi": 2, "state": "stepComplete"}``), kept in the state
        and its bytes for the binary (:meth:`loader_fields`); None without the binary."""
        block = None
        if self._block is not None:
            if self._snapshot is None:
                leaves = Leaves()
                self._snapshot = (capture(self._block, leaves, rollback=True), leaves)
            block = self._snapshot[0]       # immutable objects kept as they are: plain data in its bytes
        return FmuState(self.identity, {
            "time": self._time,
            "params": {name: value.copy() for name, value in self._params.items()},
            "inputs": {name: value.copy() for name, value in self._inputs.items()},
            "modes": {name: value.astype(np.int64) for name, value in self._modes.items()},
            "derivatives": {name: value.copy() for name, value in self._derivatives.items()},
            "last_inputs": {name: (value, at) for name, (value, at) in self._last_inputs.items()},
            "block_error": self._block_error,
            "block": block,
            "initialized": self._stepping,
            "loader": None if loader is None else dict(loader),
        })

    def loader_fields(self, state) -> tuple[dict | None, float, bool]:
        """The native binary's fields of a state of this FMU, with its time and whether it was saved
        after initialization (the binary validates them against its state machine)."""
        tree = self._own(state).tree
        return tree["loader"], tree["time"], tree["initialized"]

    @_host_independent_numerics
    def set_fmu_state(self, state) -> None:
        """Restore a state of this FMU; anything else is refused (:class:`Refused`) and changes nothing."""
        tree = self._own(state).tree
        try:
            self._check_tree(tree)
            block = snapshot = outputs = None
            if tree["block"] is not None:
                block, snapshot, outputs = self._restored_block(tree)
        except StateError as exc:
            raise Refused(str(exc)) from None
        # nothing can fail from here on
        for name in ("params", "inputs", "modes"):          # the variable getters hold these arrays
            for key, values in tree[name].items():
                getattr(self, f"_{name}")[key][:] = values
        self._derivatives = {name: np.array(value, dtype=float) for name, value in tree["derivatives"].items()}
        self._last_inputs = {name: (np.array(value, dtype=float), float(at))
                             for name, (value, at) in tree["last_inputs"].items()}
        self._time = tree["time"]
        self._stepping = tree["initialized"]
        self._use_block(block)
        self._block_error = tree["block_error"] if block is None else None
        self._snapshot, self._outputs_cache = snapshot, outputs

    def _restored_block(self, tree: dict) -> tuple[Block, tuple[dict, Leaves], dict | None]:
        """The block with the saved state, its snapshot and outputs, all checked; the live block is
        changed only if all is well.  The outputs are None (computed when read) when the saved inputs
        are not usable: a state saved after a bad input was set is a state like any other."""
        live = self._block
        same = live is not None and all(np.array_equal(tree["params"][name], value)
                                        for name, value in self._params.items())
        if same:
            block, rollback = live, (self._snapshot[0] if self._snapshot else capture(live, rollback=True))
        else:
            try:
                block, rollback = self._new_block(tree["params"]), None
            except Exception as exc:
                raise StateError(f"the parameters of the state do not define a valid block: "
                                 f"{type(exc).__name__}: {exc}") from None
        block.set_state(tree["block"])                         # checked: raises before any change
        try:
            leaves, bound = Leaves(), block.magnitude_bound
            snapshot = (capture(block, leaves, rollback=True), leaves)
            # every number restored; an immutable object (only in a state of this process) was checked when built
            fault = self._state_fault(tree["block"], None, None, bound)
            outputs = None                 # inputs that are not usable: the next step refuses, naming them
            if all(within(value, bound) for value in tree["inputs"].values()):
                outputs = block.outputs(tree["time"], tree["inputs"])
                fault = fault or self._output_fault(outputs, bound)
            if fault:
                raise StateError(f"the state is not usable: {fault}")
        except Exception as exc:
            if rollback is not None:
                block.set_state(rollback, check=False)
            if isinstance(exc, StateError):
                raise
            raise StateError(f"the state is not usable: {type(exc).__name__}: {exc}") from None
        return block, snapshot, outputs

    def _check_tree(self, tree) -> None:
        """The slave's part of a state must have exactly this FMU's variables and shapes."""
        def require(condition, what):
            if not condition:
                raise StateError(f"not a state of {self.definition.model_name}: {what}")

        require(type(tree) is dict and set(tree) == _SECTIONS, "wrong sections")
        require(type(tree["time"]) is float and math.isfinite(tree["time"]), "time")
        for section, store, dtype in (("params", self._params, np.float64), ("inputs", self._inputs, np.float64),
                                      ("modes", self._modes, np.int64)):
            values = tree[section]
            require(type(values) is dict and set(values) == set(store), f"{section}: wrong names")
            for name, value in values.items():
                require(type(value) is np.ndarray and value.dtype == dtype and value.shape == store[name].shape,
                        f"{section} {name}: wrong type or shape")
        require(all(int(m[0]) in InputMode._value2member_map_ for m in tree["modes"].values()), "modes: values")
        for section in ("derivatives", "last_inputs"):
            require(type(tree[section]) is dict and set(tree[section]) <= set(self._inputs), f"{section}: names")
        for name, value in tree["derivatives"].items():
            require(type(value) is np.ndarray and value.dtype == np.float64 and value.shape == self._inputs[name].shape,
                    f"derivatives {name}")
        for name, entry in tree["last_inputs"].items():
            require(type(entry) in (tuple, list) and len(entry) == 2 and type(entry[0]) is np.ndarray
                    and entry[0].dtype == np.float64 and entry[0].shape == self._inputs[name].shape
                    and type(entry[1]) is float and math.isfinite(entry[1]), f"last_inputs {name}")
        require(tree["block_error"] is None or type(tree["block_error"]) is str, "block_error")
        require(tree["block"] is None or type(tree["block"]) is dict, "block")
        require(type(tree["initialized"]) is bool, "initialized")
        require(not tree["initialized"] or (tree["block"] is not None and tree["block_error"] is None),
                "initialized without a block")
        loader = tree["loader"]
        require(loader is None or (type(loader) is dict and set(loader) == {"fmi", "state"}
                                   and type(loader["fmi"]) is int and type(loader["state"]) is str
                                   and len(loader["state"]) < 32), "loader")

    def serialize_fmu_state(self, state) -> bytes:
        """The bytes of ``state`` (:mod:`fmus.runtime.state_format`): the one serialized form of an FMU state."""
        state = self._own(state)
        return pack(state.identity, plain(state.tree))

    def deserialize_fmu_state(self, data: bytes) -> FmuState:
        """An FMU state from bytes of :meth:`serialize_fmu_state`; anything else is refused
        (:class:`Refused`: format, version, identity, checksum, then every section checked)."""
        try:
            tree = unpack(data, self.identity)
            self._check_tree(tree)
        except (StateFormatError, StateError) as exc:
            raise Refused(str(exc)) from None
        return FmuState(self.identity, tree)

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
