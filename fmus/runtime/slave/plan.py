"""What the native binary's one-call step (``obsfmuDoStepBatched``) exchanges with the slave, prepared once."""

from __future__ import annotations

import numpy as np

__all__ = ["BatchPlan"]


class BatchPlan:
    """The value references of one call, and the vectors whose memory the binary fills (``values``,
    ``slopes``) before the call and reads (``outputs``) after it; where they go among the FMU's inputs
    and outputs (:meth:`~fmus.runtime.slave.step.Stepping.batch_plan`)."""

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
