"""The block behind the FMU: built from the parameter values when first needed, its outputs, the faults named.

The block is built lazily, so that values set by the importer before or during initialization take
effect; ``exit_initialization_mode`` refuses parameters that define no valid block or give unusable
first outputs, naming them (docs/faults.md).
"""

from __future__ import annotations

import math

import numpy as np

from obsfmu.observers.block import MAGNITUDE_BOUND, Block
from obsfmu.observers.checks import ParameterError
from obsfmu.observers.state import Leaves, out_of_bounds, within, within_bound

from ..kinds import create_block
from .common import NUMERICAL_FAULTS, Refused, verdict
from .numerics import host_independent_numerics, quiet_numerics

__all__ = ["BlockOfParameters"]


class BlockOfParameters:
    """The block of :class:`~fmus.runtime.slave.BlockSlave`'s parameters, its outputs and the words for its faults."""

    def _stateless(self) -> bool:
        block = self._try_block()
        return block is not None and getattr(block, "stateless", False)

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
                with quiet_numerics():
                    self._use_block(self._new_block(self._params))
            except Exception as exc:  # a bad parameter set must not crash the host; callers report it
                self._block_error = f"{type(exc).__name__}: {exc}"
        return self._block

    def _use_block(self, block: Block | None) -> None:
        self._block, self._snapshot, self._outputs_cache = block, None, None
        if block is not None:
            block.caller_rolls_back = True       # the checked step restores the state of a failed step
        self._bound = MAGNITUDE_BOUND if block is None else block.magnitude_bound
        #: the fastest rate of the system (system files' adaptive observers): converged vouched for only at
        #: steps whose coupling error (h rate)^2/3 is within converged_tolerance (fmus/system/load.py)
        self._step_rate = float(np.ravel(self._params["step_rate"])[0]) \
            if "step_rate" in self._params and block is not None else 0.0
        if self._step_rate:
            block.longest_step = 0.0             # state: the longest communication step so far
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
                with quiet_numerics():
                    self._outputs_cache = block.outputs(self._time, self._inputs)
            except NUMERICAL_FAULTS as exc:       # anything else is a bug: a failure
                raise Refused(f"output {port} at t={self._time:g} cannot be computed: "
                              f"{type(exc).__name__}: {exc}") from None
        return float(self._outputs_cache[port][index])

    def get_real_output_derivatives(self, vrs, orders) -> list[float]:
        """``fmi2GetRealOutputDerivatives``: the first derivatives of outputs at the current time, from the
        block's ``derivative(t)`` (FMUs built with ``output_derivatives``: one output port).  :class:`Refused`
        for an FMU without them, an order other than 1 or a value reference that is not an output."""
        if not self.definition.output_derivatives:
            raise Refused("fmi2GetRealOutputDerivatives: this FMU provides no output derivatives "
                          "(maxOutputDerivativeOrder = 0)")
        offsets = self._output_offsets
        for vr, order in zip(vrs, orders):
            if vr not in offsets:
                raise Refused(f"fmi2GetRealOutputDerivatives: value reference {vr} is not an output")
            if order != 1:
                raise Refused(f"fmi2GetRealOutputDerivatives: order {order} for value reference {vr}: only first "
                              "derivatives (maxOutputDerivativeOrder = 1)")
        block = self._try_block()
        if block is None:
            raise Refused(f"output derivatives cannot be computed: the parameters do not define a valid block: "
                          f"{self._block_error}")
        with quiet_numerics():
            derivative = np.atleast_1d(np.asarray(block.derivative(self._time), dtype=float))
        return derivative[[offsets[vr] for vr in vrs]].tolist()

    def _output_fault(self, outputs: dict[str, np.ndarray], bound: float) -> str | None:
        """The first output element that is not finite or beyond ``bound``."""
        for port, values in outputs.items():
            values = np.asarray(values, dtype=float)
            if not within(values, bound):
                names = next(p.element_names for p in self.definition.outputs if p.name == port)
                i = int(np.argmax(np.where(np.isfinite(values), np.abs(values), np.inf)))
                return f"output {names[i]} = {verdict(values[i], bound)}"
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
        return f"state {path} = {verdict(value, bound)}"

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

    # ------------------------------------------------------------------ the start of a run
    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        if not math.isfinite(start_time):
            raise Refused(f"start time {start_time} is not finite")
        self._time = float(start_time)

    @host_independent_numerics
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
            except NUMERICAL_FAULTS as exc:
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
