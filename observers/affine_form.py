"""The affine form of a linear block: what a compiled step kernel needs to advance it (issue 39).

A continuous linear block -- the LTI plant, the Luenberger observer, state feedback with or without integral
action -- advances its state exactly over a step whose inputs are linear, ``w(t + s) = w0 + s dw``::

    x(t + h) = Phi(h) x(t) + G0(h) w0 + G1(h) dw                  (observers.integrators.LinearPropagator)

and its outputs are affine in the state and the inputs, port by port::

    out = C x + D w + e

``w`` is the block's input ports in the order of :attr:`AffineForm.inputs`, followed by a constant 1 when
:attr:`AffineForm.constant` (a linearised observer's offsets).  This is the same arithmetic as the block's own
``advance`` and ``outputs``: the FMU's C kernel (``fmus/native/kernel.h``) evaluates it with the matrices the
block itself uses, so both paths agree to round-off.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = ["AffineForm", "output_map"]


@dataclass(frozen=True)
class AffineForm:
    """``x(t + h) = Phi x + G0 w0 + G1 dw``, ``out = C x + D w + e`` (module docstring)."""

    state: str                      #: the block's attribute holding ``x`` ("" for a block without state)
    size: int                       #: ``n``, the length of ``x``
    inputs: tuple[str, ...]         #: the block's input ports, in the order of the columns of ``w``
    constant: bool                  #: ``w`` ends with a constant 1
    #: ``h -> (Phi, G0, G1)``, ``(n, n)``, ``(n, W)``, ``(n, W)`` (``W`` columns of ``w``); None when n = 0
    step: Callable[[float], tuple[np.ndarray, np.ndarray, np.ndarray]] | None
    #: output port -> ``(C, D, e)``: ``(q, n)``, ``(q, m)`` over the input ports (no constant column), ``(q,)``
    outputs: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]


def output_map(C, D=None, e=None, inputs: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(C, D, e)`` of one output port, ``D`` zero (``q x inputs``) and ``e`` zero when not given."""
    C = np.atleast_2d(np.asarray(C, dtype=float))
    q = C.shape[0]
    D = np.zeros((q, inputs)) if D is None else np.asarray(D, dtype=float).reshape(q, inputs)
    return C, D, np.zeros(q) if e is None else np.asarray(e, dtype=float).reshape(q)
