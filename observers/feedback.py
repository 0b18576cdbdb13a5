"""Static state feedback ``u = -K x_hat + r`` (paper 002, eq. (4))."""

from __future__ import annotations

from typing import Mapping

import numpy as np

from .block import Block, Segment
from .checks import as_matrix

__all__ = ["StateFeedback"]


class StateFeedback(Block):
    """``u = -K x_hat + r``; ``K`` is ``(m, n)``.

    Ports: inputs ``x_hat`` (n), ``r`` (m); output ``u`` (m).  The output
    depends on the current inputs (direct feedthrough) and there is no state.
    """

    feedthrough = True
    stateless = True
    not_state = ("K",)

    def __init__(self, K):
        self.K = as_matrix("K", K)
        m, n = self.K.shape
        self.input_sizes = {"x_hat": n, "r": m}
        self.output_sizes = {"u": m}

    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {"u": -self.K @ inputs["x_hat"] + inputs["r"]}

    def advance(self, t: float, h: float, inputs: Mapping[str, Segment]) -> None:
        """Nothing to integrate: the block is static."""
