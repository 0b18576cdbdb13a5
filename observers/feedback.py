"""State feedback: static ``u = -K x_hat + r`` (paper 002, eq. (4)), or with integral action on the output error,
``u = -K x_hat - K_i z``, ``z' = y - r``: in steady state ``z' = 0``, so ``y = r`` whatever a constant
disturbance or model error (the classical servo design: the gains place the poles of the augmented loop
``[[A, 0], [C, 0]] - [[B], [0]] [K, K_i]``)."""

from __future__ import annotations

from typing import Mapping

import numpy as np

from .kernel_forms import AffineForm, output_map
from .block import Block, Segment
from .checks import ParameterError, as_matrix, as_vector

__all__ = ["StateFeedback", "IntegralStateFeedback", "integral_augmented"]


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

    def kernel_form(self) -> AffineForm:
        """The compiled kernel's form: no state, ``u = [-K, I] [x_hat; r]``."""
        m, n = self.K.shape
        return AffineForm("", 0, ("x_hat", "r"), False, None,
                          {"u": output_map(np.zeros((m, 0)), np.hstack([-self.K, np.eye(m)]), inputs=n + m)})


class IntegralStateFeedback(Block):
    """``u = -K x_hat - K_i z``, ``z' = y - r``; ``K`` is ``(m, n)``, ``K_i`` ``(m, p)``.

    Ports: inputs ``x_hat`` (n), ``y`` (p, the measured output), ``r`` (p, its reference); output ``u`` (m).
    ``z`` (p) is the integral of ``y - r``, advanced exactly for inputs linear over a step; ``u`` depends on the
    current ``x_hat`` (direct feedthrough), ``y`` and ``r`` act through ``z`` only.
    """

    feedthrough = True
    not_state = ("K", "K_i")

    def __init__(self, K, K_i, z0=None):
        self.K = as_matrix("K", K)
        m, n = self.K.shape
        self.K_i = as_matrix("K_i", K_i)
        if self.K_i.shape[0] != m:
            raise ParameterError(f"K_i: expected {m} rows (one per input, as K), got {self.K_i.shape[0]}")
        p = self.K_i.shape[1]
        self.z = np.zeros(p) if z0 is None else as_vector("z0", z0, p)
        self.input_sizes = {"x_hat": n, "y": p, "r": p}
        self.output_sizes = {"u": m}

    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {"u": -self.K @ inputs["x_hat"] - self.K_i @ self.z}

    def advance(self, t: float, h: float, inputs: Mapping[str, Segment]) -> None:
        """``z(t + h) = z + h e(t) + h^2 / 2 e'``, ``e = y - r`` linear over the step (exact)."""
        y, r = inputs["y"], inputs["r"]
        self.z = self.z + h * (y.start - r.start) + 0.5 * h * h * (y.slope - r.slope)

    def kernel_form(self) -> AffineForm:
        """The compiled kernel's form: ``z(t + h) = z + h [0, I, -I] w0 + h^2/2 [0, I, -I] dw`` over
        ``w = [x_hat; y; r]``, ``u = -K_i z - [K, 0, 0] w``."""
        m, n = self.K.shape
        p = self.K_i.shape[1]
        error = np.hstack([np.zeros((p, n)), np.eye(p), -np.eye(p)])      # e = y - r

        def step(h: float):
            return np.eye(p), h * error, 0.5 * h * h * error
        return AffineForm("z", p, ("x_hat", "y", "r"), False, step,
                          {"u": output_map(-self.K_i, np.hstack([-self.K, np.zeros((m, 2 * p))]), inputs=n + 2 * p)})



def integral_augmented(A, B, C) -> tuple[np.ndarray, np.ndarray]:
    """The plant with the integrators of its output error, ``[x; z]' = A_a [x; z] + B_a u``,
    ``A_a = [[A, 0], [C, 0]]``, ``B_a = [[B], [0]]``: a gain ``[K, K_i]`` placing ``eig(A_a - B_a [K, K_i])``
    is the integral action of :class:`IntegralStateFeedback`."""
    A, C = np.atleast_2d(np.asarray(A, dtype=float)), np.atleast_2d(np.asarray(C, dtype=float))
    n, p = A.shape[0], C.shape[0]
    B = np.asarray(B, dtype=float).reshape(n, -1)
    return (np.block([[A, np.zeros((n, p))], [C, np.zeros((p, p))]]),
            np.vstack([B, np.zeros((p, B.shape[1]))]))
