"""One co-simulation round: every instance steps once, from ``t`` to ``t + h`` (:class:`Stepper`).

Two implementations of the same arithmetic, chosen in one place (:class:`Stepper`):

* the Python round -- Gauss-Seidel (instances step one after another in the listed order, each from the
  newest outputs) or Jacobi (every instance from the outputs at ``t``, direct-feedthrough blocks then
  re-evaluated);
* :class:`NativeRound` -- the Gauss-Seidel round in one call of an obsfmu binary (``obsfmuRound``,
  fmus/native/loader.c), used when every instance is an obsfmu FMI 2.0 FMU with the one-call step
  (``obsfmuDoStepPlanned``) and one of their binaries has the round.  The Python round costs ~15 numpy
  operations and a ctypes call per instance and round, several microseconds that a co-simulation of
  small blocks pays every step; tests/fmus/master/test_round.py proves both give the same numbers bit for bit.

Coupling.  ``linear`` feeds each input as a straight line over the step (FMI input derivatives): it
*interpolates* between the producer's outputs at ``t`` and ``t + h`` when the producer has already
stepped (Gauss-Seidel), and *extrapolates* from the previous communication point otherwise; ``hold`` is
the plain zero-order hold.  The native round keeps that history (the outputs at the last two
communication points) in buffers of its own, which the stepper's ``now`` and ``before`` then are;
whoever rebinds them (the adaptive master's restore, the initial slope probe) is noticed and the buffers
reloaded.
"""

from __future__ import annotations

from ctypes import PYFUNCTYPE, Structure, addressof, c_double, c_int, c_size_t, c_void_p, cast

import numpy as np

from .errors import WARNING, call, check
from .instance import Instance
from .loops import LoopSolver, find_loops

__all__ = ["Stepper", "NativeRound"]


class Stepper:
    """One communication round of all instances, in Gauss-Seidel or Jacobi order.

    Holds the shared output array (``live``; every instance's ``fmi2GetReal`` writes its
    slice), the outputs at the current communication point (``now``) and at the previous one
    (``before``, ``h_before``) -- the history the linear coupling extrapolates from.
    """

    def __init__(self, instances: dict[str, Instance], logger, jacobi: bool, linear: bool):
        self.instances, self.logger, self.jacobi, self.linear = instances, logger, jacobi, linear
        self.order = list(instances.values())
        self.live = np.zeros(sum(len(inst.outputs) for inst in instances.values()))
        offset = 0
        for inst in self.order:
            inst.bind_outputs(self.live[offset:offset + len(inst.outputs)])  # a view: written in place
            offset += len(inst.outputs)
        self.now = self.live.copy()
        self.before: np.ndarray | None = None
        self.h_before = 0.0
        self.feedthrough = [inst for inst in self.order if inst.feedthrough]
        #: instances whose binary steps in one call (set inputs, step, read outputs: obsfmuDoStepPlanned)
        self.batched = {inst for inst in self.order if inst.batched}
        #: the whole Gauss-Seidel round in one call of a binary, when every instance can
        self.native = None if jacobi else NativeRound.of(self.order, self.live, linear)
        loops = find_loops(self.order)
        #: solves the algebraic loops at every communication point (None: there are none)
        self.loops = LoopSolver(loops, self.live, logger) if loops else None
        members = {inst for loop in loops for inst in loop.members}
        self._downstream = [inst for inst in self.feedthrough if inst not in members]

    def settle(self, passes: int) -> None:
        """Propagate outputs to inputs until direct-feedthrough chains are consistent."""
        for _ in range(passes):
            for inst in self.order:
                inst.input_values[:] = self.live[inst.input_sources]
                check(inst, self.logger, "setting inputs", inst.set_inputs())
                check(inst, self.logger, "reading outputs", inst.refresh_outputs())

    def solve_loops(self, t: float) -> None:
        """Make the algebraic loops consistent at ``t`` (:mod:`.loops`), then pass their outputs on
        once to the other direct-feedthrough instances."""
        if self.loops is None:
            return
        self.loops.solve(t)
        for inst in self._downstream:
            inst.input_values[:] = self.live[inst.input_sources]
            check(inst, self.logger, "setting inputs", inst.set_inputs())
            check(inst, self.logger, "reading outputs", inst.refresh_outputs())

    def mark_communication_point(self) -> None:
        self.now = self.live.copy()

    def round(self, t: float, h: float) -> None:
        """Every instance from ``t`` to ``t + h``: in one call of a binary when it can, else in Python."""
        native = self.native
        if native is not None and self.linear == native.linear:
            status, failed = native.run(t, h, self.now, self.before, self.h_before)
            if status > WARNING:
                check(failed or self.order[0], self.logger,
                      lambda: f"doStep(t={t:.9g}, h={h:.3g}) with its inputs", status)
            self.before, self.now, self.h_before = native.before, native.now, h
            if self.loops is not None:
                self.solve_loops(t + h)
                self.now[:] = self.live               # the native round's own history buffer
            return
        live, now, linear = self.live, self.now, self.linear
        if linear:
            slopes = (now - self.before) / self.h_before if self.before is not None else np.zeros_like(now)
        source = now if linear or self.jacobi else live
        for inst in self.order:
            if inst.input_vrs:
                sources = inst.input_sources
                values = inst.input_values
                values[:] = source[sources]
                if linear:
                    derivatives = inst.input_slopes
                    derivatives[:] = slopes[sources]
                    if not self.jacobi and inst.stepped_index.size:  # stepped already: interpolate t -> t + h
                        derivatives[inst.stepped_index] = (live[inst.stepped_sources]
                                                           - values[inst.stepped_index]) / h
            if inst in self.batched:
                status = inst.step(t, h, linear)
                if status > WARNING:
                    check(inst, self.logger, lambda: f"doStep(t={t:.9g}, h={h:.3g}) with its inputs", status)
                continue
            if inst.input_vrs:
                status = inst.set_inputs(linear)
                if status > WARNING:
                    check(inst, self.logger, "setting inputs", status)
            status = inst.do_step(t, h)
            if status > WARNING:
                check(inst, self.logger, lambda: f"doStep(t={t:.9g}, h={h:.3g})", status)
            status = inst.refresh_outputs()
            if status > WARNING:
                check(inst, self.logger, "reading outputs", status)
        if self.jacobi and self.feedthrough:
            self.settle(len(self.feedthrough))
        self.solve_loops(t + h)
        self.before, self.h_before = now, h
        self.now = live.copy()

    def probe_initial_slopes(self, t: float, delta: float) -> None:
        """Estimate the outputs' slopes at the first point by a tiny held step, then roll back.

        Without history the first step of the linear coupling would hold its
        inputs (first order); the adaptive master's error control would then
        shrink that step by orders of magnitude.
        """
        linear, saved = self.linear, self.save()
        self.linear = False
        self.round(t, delta)
        slopes = (self.live - saved[2]) / delta
        self.restore(saved)
        self.free(saved)
        self.linear = linear
        self.before, self.h_before = self.now - delta * slopes, delta

    # -- rollback (adaptive master)
    def save(self):
        states = [call(inst, self.logger, "getFMUstate", inst.get_state) for inst in self.order]
        before = None if self.before is None else self.before.copy()
        return states, self.live.copy(), self.now.copy(), before, self.h_before

    def restore(self, saved) -> None:
        states, live, now, before, h_before = saved
        for inst, state in zip(self.order, states):
            call(inst, self.logger, "setFMUstate", inst.set_state, state)
        self.live[:] = live
        self.now, self.before, self.h_before = now.copy(), None if before is None else before.copy(), h_before

    def free(self, saved) -> None:
        for inst, state in zip(self.order, saved[0]):
            inst.free_state(state)


class _Member(Structure):
    """``ObsfmuRoundMember``"""
    _fields_ = [("step", c_void_p), ("component", c_void_p), ("plan", c_void_p), ("source", c_void_p),
                ("stepped", c_void_p)]


class _Round(Structure):
    """``ObsfmuRound``"""
    _fields_ = [("nMembers", c_size_t), ("member", c_void_p), ("nOutputs", c_size_t), ("live", c_void_p),
                ("now", c_void_p), ("before", c_void_p), ("slope", c_void_p), ("hBefore", c_double),
                ("linear", c_int)]


_PROTOTYPE = PYFUNCTYPE(c_int, c_void_p, c_double, c_double, c_void_p)   # the GIL held: the steps run Python


class NativeRound:
    """``obsfmuRound`` over the instances of a stepper, with the arrays it reads and writes (built once)."""

    @classmethod
    def of(cls, instances: list, live: np.ndarray, linear: bool) -> "NativeRound | None":
        """The round of ``instances`` (in stepping order, Gauss-Seidel), or None if one of them cannot
        take part (not an obsfmu FMI 2.0 binary with the one-call step) or no binary has the round."""
        if not instances or not all(inst.batched for inst in instances):
            return None
        dll = next((inst.slave.dll for inst in instances if hasattr(inst.slave.dll, "obsfmuRound")), None)
        return None if dll is None else cls(instances, live, linear, _PROTOTYPE(("obsfmuRound", dll)))

    def __init__(self, instances: list, live: np.ndarray, linear: bool, function):
        self.instances, self.function, self.live, self.linear = instances, function, live, linear
        self.now, self.before, slope = np.zeros(live.size), np.zeros(live.size), np.zeros(live.size)
        self._keep = [slope]                      # arrays the C side points into
        members = (_Member * len(instances))()
        for member, inst in zip(members, instances):
            source = np.ascontiguousarray(inst.input_sources, dtype=np.uintp)
            stepped = np.ascontiguousarray(inst.stepped_before, dtype=np.uint8)
            self._keep += [source, stepped]
            member.step = cast(inst.slave.dll.obsfmuDoStepPlanned, c_void_p).value
            member.component = inst.slave.component
            member.plan = inst.plan_address(linear)
            member.source, member.stepped = source.ctypes.data, stepped.ctypes.data
        self._members = members
        self.struct = _Round(len(instances), addressof(members), live.size, live.ctypes.data, self.now.ctypes.data,
                             self.before.ctypes.data, slope.ctypes.data, 0.0, int(linear))
        self._address = addressof(self.struct)
        self._failed = c_size_t(0)
        self._failed_address = addressof(self._failed)

    def run(self, t: float, h: float, now: np.ndarray, before: np.ndarray | None, h_before: float):
        """One round from the history ``now``, ``before`` (None: none yet) and ``h_before``: the status
        and the instance that failed (None if the round completed, the history then in :attr:`now`,
        :attr:`before`, ``h``)."""
        if now is not self.now or (before is not None and before is not self.before):
            now, before = np.array(now), None if before is None else np.array(before)   # may be our buffers
            self.now[:] = now
            if before is not None:
                self.before[:] = before
        self.struct.hBefore = 0.0 if before is None else h_before
        status = self.function(self._address, t, h, self._failed_address)
        failed = self._failed.value
        return status, (self.instances[failed] if failed < len(self.instances) else None)
