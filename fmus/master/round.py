"""The master's Gauss-Seidel round in one call of an obsfmu binary (``obsfmuRound``, fmus/native/loader.c).

A round of :class:`~fmus.master._Stepper` in Python gathers every instance's inputs from the shared
output vector, computes their slopes, and calls each binary's one-call step through ctypes: ~15
numpy operations and a ctypes call per instance and round, several microseconds that a
co-simulation of small blocks pays every step.  When every instance is an obsfmu FMI 2.0 FMU with
the one-call step (``obsfmuDoStepPlanned``) and one of their binaries has ``obsfmuRound``, the
whole round is one call: the same arithmetic in C, the instances' steps called there directly.

The round keeps the coupling's history (the outputs at the last two communication points) in
buffers of its own, which the stepper's ``now`` and ``before`` then are; whoever rebinds them (the
adaptive master's restore, the initial slope probe) is noticed and the buffers reloaded.
"""

from __future__ import annotations

from ctypes import PYFUNCTYPE, Structure, addressof, c_double, c_int, c_size_t, c_void_p, cast

import numpy as np

__all__ = ["NativeRound"]


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
        if not instances or not all(getattr(inst, "batched", False) and hasattr(inst.slave, "dll")
                                    for inst in instances):
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
