"""The step of an FMU: one checked step, whether its inputs come from ``set_real`` or from the binary's vectors.

``do_step`` takes the inputs as ``set_real`` and ``set_real_input_derivatives`` left them;
``step_batched`` -- the native binary's one-call step, ``obsfmuDoStepBatched`` -- takes them from the
vectors of a :class:`~.plan.BatchPlan`.  Both hand :meth:`Stepping._step` the same thing: the inputs
at the step start, their slopes and which ports follow a slope (the other ports follow their
``<port>_interpolation`` mode).  It does the rest: the input segments, the checked advance and
outputs (:meth:`Stepping._checked_step`), the record of the inputs at the end.

Every step either succeeds with a finite state or changes nothing: NaN/inf/huge inputs and input
derivatives, a step longer than the block's sub-step budget, a failure inside the block, or a new
state or outputs that are not finite or beyond the block's ``magnitude_bound`` -- the step is rolled
back, one line naming the input or parameter at fault is logged at Discard level and the step returns
False (fmi2Discard); a bug inside a block is logged at Error level (docs/faults.md).
"""

from __future__ import annotations

import math

import numpy as np
from pythonfmu.enums import Fmi2Status

from obsfmu.observers.block import Block, Segment
from obsfmu.observers.state import Leaves, StateError, capture, within, within_bound

from .common import EXTRAPOLATE, INTERPOLATE, NUMERICAL_FAULTS, Refused, verdict
from .numerics import host_independent_numerics
from .plan import BatchPlan

__all__ = ["Stepping"]


class Stepping:
    """The step of :class:`~fmus.runtime.slave.BlockSlave`: its two entry points, the one step, the record of the inputs."""

    # ------------------------------------------------------------------ the entry points: where the inputs come from
    @host_independent_numerics
    def do_step(self, current_time, step_size):
        return self._do_step(current_time, step_size)

    def _do_step(self, t: float, h: float) -> bool:
        """The step of the inputs as set port by port: their values, and the slopes of those given a derivative."""
        if self._block is None or self._bad or not (0.0 < h < math.inf and math.isfinite(t)):
            return self._refuse_before(t, h)
        derivatives, flat, slices = self._derivatives, self._input_flat, self._input_slices
        slope, moving, held = None, (), list(slices)
        if derivatives:
            slope = np.zeros(flat.size)
            moving = tuple((port, where) for port, where in slices.items() if port in derivatives)
            held = [port for port in slices if port not in derivatives]
            for port, where in moving:
                slope[where] = derivatives[port]
        return self._step(t, h, flat.copy(), slope, moving, held)

    @host_independent_numerics
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
        if self._feedthrough:                  # set_real's part: the inputs change
            self._outputs_cache = None
        flat, values, slopes = self._input_flat, plan.values, plan.slopes
        if plan.in_order:                                 # every input, in order: whole vectors
            flat[:] = values
            start, slope = values.copy(), slopes.copy()   # new vectors: the block may keep views of them
        else:
            flat[plan.positions] = values
            start, slope = flat.copy(), np.zeros(flat.size)
            slope[plan.positions] = slopes
        return self._step(t, h, start, slope, plan.given, plan.held, plan)

    def _step_by_calls(self, plan: BatchPlan, t: float, h: float) -> bool:
        """:meth:`step_batched` as the separate calls it stands for (what names a fault, and the rare cases)."""
        self.set_real(plan.input_vrs, plan.values.tolist())
        if plan.derivatives and plan.input_vrs:
            self.set_real_input_derivatives(plan.input_vrs, [1] * len(plan.input_vrs), plan.slopes.tolist())
        if not self._do_step(t, h):
            return False
        self._write_outputs(plan, self._outputs_cache)
        return True

    def batch_plan(self, input_vrs, derivatives, output_vrs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Prepare :meth:`step_batched` for these value references: the vectors of input values, input
        slopes (used if ``derivatives``) and outputs that the native binary fills and reads.

        :class:`Refused` names a value reference that is not a real input (or is given twice) or not
        an output.
        """
        positions, offsets = [], self._output_offsets
        flat_of = self._input_positions()
        for vr in input_vrs:
            if vr not in flat_of:
                raise Refused(f"value reference {vr} is not a real input")
            positions.append(flat_of[vr])
        if len(set(positions)) != len(positions):
            raise Refused("a value reference is given twice among the inputs of one step")
        unknown = [vr for vr in output_vrs if vr not in offsets]
        if unknown:
            raise Refused(f"value reference {unknown[0]} is not an output")
        plan = BatchPlan(input_vrs, derivatives, output_vrs, positions, self._input_slices,
                         [offsets[vr] for vr in output_vrs], len(offsets))
        self._batch = plan
        return plan.values, plan.slopes, plan.outputs

    # ------------------------------------------------------------------ the step
    def _step(self, t: float, h: float, start: np.ndarray, slope: np.ndarray | None, moving, held,
              plan: BatchPlan | None = None) -> bool:
        """The one step of an FMU, from ``start`` (every input element at the step start, a new vector) and
        ``slope``: ``moving`` lists ``(port, where)`` of the ports that follow their slope over the step, in
        declaration order (``where`` None: the only port, the whole vectors); the ports ``held`` follow their
        ``<port>_interpolation`` mode.  With ``plan`` (:meth:`step_batched`) the outputs go into its vector.
        True if the step was taken: the inputs are then at the step end and recorded."""
        block = self._block
        derivatives, ends, segments, end = {}, {}, {}, None
        if moving:
            end = slope * h
            end += start
            for port, where in moving:
                if where is None:
                    derivatives[port], ends[port], segments[port] = slope, end, Segment(start, slope)
                else:
                    derivatives[port], ends[port] = slope[where], end[where]
                    segments[port] = Segment(start[where], derivatives[port])
        self._derivatives = derivatives          # the slopes of the step (a fault names them)
        if block.stateless:
            segments = None
        elif held:                               # every port in declaration order, as in moving
            segments = {port: segments[port] if port in segments else self._held_segment(port, t, h)
                        for port in self._input_slices}
        staged = plan if plan is not None and plan.output_order is None else None
        if not self._checked_step(t, h, block, segments, ends, staged):
            return False
        if moving:                               # the inputs at the end (the held ones as they were)
            if held:
                for port, where in moving:
                    self._input_flat[where] = end[where]
            else:
                self._input_flat[:] = end
        at_end = tuple(port for port in held if self._modes[port][0] == INTERPOLATE) if held else ()
        self._pending_record, self._derivatives = (start, end, held, at_end, t, t + h), {}
        if plan is not None and staged is None:
            self._write_outputs(plan, self._outputs_cache)
        return True

    def _held_segment(self, port: str, t: float, h: float) -> Segment:
        """Input ``port`` over a step it has no derivative for: as its ``<port>_interpolation`` mode says."""
        value = self._inputs[port]
        mode = self._modes[port][0]
        previous, previous_time = self._last_inputs.get(port, (value, t))
        if mode == INTERPOLATE:
            return Segment.between(previous, value, h)
        if mode == EXTRAPOLATE and previous_time < t:
            return Segment(value.copy(), (value - previous) / (t - previous_time))
        return Segment.hold(value.copy())

    def _checked_step(self, t: float, h: float, block: Block, segments: dict | None, ends: dict,
                      plan: BatchPlan | None = None) -> bool:
        """Advance ``block`` over the input ``segments`` (None: a stateless block) and compute its outputs
        with the inputs at the step end (``ends``: those that moved); keep the result only if the new
        state, the inputs at the end and the outputs are all finite and within the bound, else roll back
        and refuse (docs/faults.md).  True if the step was taken.

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
                if self._step_rate:
                    block.longest_step = max(block.longest_step, h)
                leaves = Leaves()
                tree = capture(block, leaves, rollback=True)
            outputs = block.outputs(t + h, at_end)
            if self._step_rate:
                outputs = self._vouched(outputs, block)
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
            if isinstance(exc, NUMERICAL_FAULTS) and not isinstance(exc, StateError):
                return self._refuse(t, h, self._fault(tree, leaves, checked, ends, outputs, exc))
            return self._refuse(t, h, f"{type(exc).__name__}: {exc} (a bug: please report)", Fmi2Status.error)
        if fault:
            if before is not None:
                block.set_state(before[0], check=False)
            return self._refuse(t, h, fault)
        self._time = t + h
        self._snapshot = None if tree is None else (tree, leaves)
        self._outputs_cache = outputs
        if not self._sampling_noted and getattr(block, "inexact_instant", None) is not None:
            self._note_inexact_sampling(block.inexact_instant, t, h)
        return True

    def _vouched(self, outputs: dict, block) -> dict:
        """``converged`` held at 0 while the longest step so far gives a coupling error ``(h rate)^2 / 3`` (linear
        coupling; README "Choosing the communication step") above ``converged_tolerance``: the family's error
        bound cannot see it (issue 36: a flag of 1 with a parameter error of 0.15 at h = 0.5 s).  Logged once."""
        tolerance = float(np.ravel(self._params["converged_tolerance"])[0])
        error = (block.longest_step * self._step_rate) ** 2 / 3.0
        if error <= tolerance or not outputs["converged"][0]:
            return outputs
        if not self._step_noted:
            self._step_noted = True
            self.log(f"converged held at 0: communication steps up to h = {block.longest_step:.3g} against the "
                     f"system's fastest rate step_rate = {self._step_rate:.3g} give a coupling error of about "
                     f"(h step_rate)^2/3 = {error:.2g}, above converged_tolerance = {tolerance:g}, which the "
                     f"estimator's error bound cannot see; steps of at most "
                     f"{(3.0 * tolerance) ** 0.5 / self._step_rate:.3g} let the flag vouch for the estimate",
                     Fmi2Status.warning)
        return {**outputs, "converged": np.zeros(1)}

    def _note_inexact_sampling(self, instant: float, t: float, h: float) -> None:
        """Once: a discrete block's sample instant fell inside a step (observers.sampling)."""
        self._sampling_noted = True
        self.log(f"sample instant t = {instant:.9g} lies inside the communication step [{t:.9g}, {t + h:.9g}]: "
                 f"the block samples its inputs there from the step's input line, exact only when every sample "
                 f"instant is a communication point (a step that divides the sample time)",
                 Fmi2Status.warning)

    def _write_outputs(self, plan: BatchPlan, outputs: dict) -> None:
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

    # ------------------------------------------------------------------ the inputs recorded
    @property
    def _last_inputs(self) -> dict[str, tuple[np.ndarray, float]]:
        """Each input's last recorded value and the time it belongs to: after a step, its value at the end
        (held ports: as they were; an interpolated one belongs to the step end), read from the step's
        vectors when first needed."""
        if self._pending_record is not None:
            start, end, held, at_end, time, end_time = self._pending_record
            self._pending_record = None
            self._recorded = {port: (start[where], end_time if port in at_end else time) if port in held
                              else (end[where], end_time) for port, where in self._input_slices.items()}
        return self._recorded

    @_last_inputs.setter
    def _last_inputs(self, record: dict[str, tuple[np.ndarray, float]]) -> None:
        self._pending_record, self._recorded = None, record

    def _remember_inputs(self, time: float) -> None:
        """Record each input at ``time``, before the first step; derivatives given so far belong to no step."""
        last = self._last_inputs
        for port, value in self._inputs.items():
            last[port] = (value.copy(), time)
        self._derivatives.clear()
        if self._bad:
            self._bad = {name: value for name, value in self._bad.items() if not name.startswith("der(")}

    # ------------------------------------------------------------------ refusals
    def _refuse(self, t: float, h: float, reason: str, status=Fmi2Status.discard) -> bool:
        self.log(f"do_step(t={t:g}, h={h:g}) refused, state unchanged: {reason}", status)
        return False

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
            return self._refuse(t, h, f"{kind} {name} = {verdict(value, self._bound)}")
        return self._do_step(t, h)                # the block was built just now

    def _fault(self, tree, leaves, checked, ends, outputs, error) -> str:
        """What the test of :meth:`_checked_step` (or ``error``, raised by the step) found wrong, in words."""
        for port, end in ends.items():
            if not within(end, self._bound):
                return f"input {port} at the step end (value + h * derivative) = {verdict(end, self._bound)}"
        if tree is not None:
            fault = self._state_fault(tree, leaves, checked, self._bound)
            if fault:
                return f"after the step {fault} ({self._suspects()})"
        if error is not None:
            return f"{type(error).__name__}: {error}"
        fault = self._output_fault(outputs, self._bound) or "a value out of bounds"
        return f"after the step {fault} ({self._suspects()})"
