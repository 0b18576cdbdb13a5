"""What a compiled step kernel needs of a block to advance it in C (issue 39): the block's *kernel form*.

A block that offers ``kernel_form()`` returns one of these (or None: it steps in Python); the FMU's C kernel
(``fmus/native/kernel.h``) then evaluates the same arithmetic as the block's own ``advance`` and ``outputs``, so
both paths agree to round-off.

:class:`AffineForm` -- a continuous linear block (the LTI plant, the Luenberger observer, state feedback with or
without integral action), exact over a step whose inputs are linear, ``w(t + s) = w0 + s dw``::

    x(t + h) = Phi(h) x(t) + G0(h) w0 + G1(h) dw                  (observers.integrators.LinearPropagator)
    out = C x + D w + e                                            (each output port)

``w`` is the block's input ports in the order of :attr:`AffineForm.inputs`, followed by a constant 1 when
:attr:`AffineForm.constant` (a linearised observer's offsets).

:class:`ExpressionForm` -- a continuous plant of expressions (:mod:`plants.expression`), ``x' = f(t, x, u, p)``,
``y = h(t, x, u, p)`` integrated by :func:`~observers.integrators.rk4_controlled`; ``f`` and ``h`` are compiled to
C from the same texts (:mod:`observers.expressions_c`) when the FMU is built.

:class:`PackedForm` -- a block with a C kernel of its own (``kind``; paper 001's plant and observer,
:mod:`observers.ltv.kernel`): its whole state packed into one vector, the kernel's settings and constants.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["AffineForm", "ExpressionForm", "PackedForm", "output_map"]


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


@dataclass(frozen=True)
class ExpressionForm:
    """``x' = f(t, x, u, p)``, outputs ``y = h(t, x, u, p)`` and ``x``, by ``rk4_controlled`` (module docstring)."""

    state: str                      #: the block's attribute holding ``x``
    size: int                       #: ``n``
    inputs: tuple[str, ...]         #: ``("u",)``, or ``()`` for a plant without input
    parameters: np.ndarray          #: ``p``, the vector the expressions read
    #: ``(max_substep, rtol, atol, substep_budget)`` of the sub-steps
    settings: tuple[float, float, float, float]
    outputs: tuple[str, str] = ("y", "x")


@dataclass(frozen=True)
class PackedForm:
    """A block stepped by a C kernel of its own: its state as one vector (module docstring)."""

    kind: str                       #: which kernel ("ltv-observer", "ltv-plant")
    size: int                       #: the length of the packed state
    inputs: tuple[str, ...]         #: the block's input ports the kernel reads (scalars)
    outputs: tuple[str, ...]        #: the output ports, in the order the kernel writes them
    #: the kernel's settings by name, in the order of its C enum; the FMU fills ``input_<port>`` (where the port is
    #: among the FMU's inputs), ``step_rate``, ``x_longest``, ``x_noted`` and ``x_size`` (the slave appends the
    #: longest step and whether a held converged flag was logged to the packed state)
    settings: dict[str, float]
    parameters: np.ndarray          #: the constants the kernel reads
    pack: Callable[[], np.ndarray]  #: the block's state as the vector
    unpack: Callable[[np.ndarray], None]   #: the vector back into the block (a new state, rebound)


def output_map(C, D=None, e=None, inputs: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(C, D, e)`` of one output port, ``D`` zero (``q x inputs``) and ``e`` zero when not given."""
    C = np.atleast_2d(np.asarray(C, dtype=float))
    q = C.shape[0]
    D = np.zeros((q, inputs)) if D is None else np.asarray(D, dtype=float).reshape(q, inputs)
    return C, D, np.zeros(q) if e is None else np.asarray(e, dtype=float).reshape(q)
