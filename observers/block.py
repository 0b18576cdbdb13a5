"""The interface every simulated object (plant, observer, controller) offers.

A *block* is a causal dynamic system advanced over communication steps.  It
is plain Python/numpy, usable without FMI; the FMU adapter in
``fmus/slave.py`` wraps any block generically.

* ``outputs(t, inputs)`` returns the outputs at the current time ``t`` as a
  dict of 1-D arrays.  A block whose outputs depend on its current inputs
  (direct feedthrough, e.g. ``u = -K x_hat + r``) sets ``feedthrough = True``.
* ``advance(t, h, inputs)`` moves the state from ``t`` to ``t + h``.  Each
  input is a :class:`Segment`: the value at ``t`` plus a slope, so a block
  can integrate a linearly interpolated input exactly instead of holding it.
* ``get_state()`` / ``set_state()`` copy the complete state (for FMU state
  save/restore); the default copies every attribute.

Inputs and outputs are named ports; their sizes are fixed at construction.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any, ClassVar, Mapping

import numpy as np

__all__ = ["Segment", "Block"]


@dataclass(frozen=True)
class Segment:
    """An input over one step: ``value(t0 + s) = start + s * slope``, ``0 <= s <= h``."""

    start: np.ndarray
    slope: np.ndarray

    @classmethod
    def hold(cls, value) -> "Segment":
        value = np.asarray(value, dtype=float)
        return cls(value, np.zeros_like(value))

    @classmethod
    def between(cls, start, end, h: float) -> "Segment":
        start = np.asarray(start, dtype=float)
        return cls(start, (np.asarray(end, dtype=float) - start) / h)

    def at(self, s: float) -> np.ndarray:
        """Value ``s`` seconds after the step start."""
        return self.start + s * self.slope


class Block:
    """Base class of plants, observers and controllers (see module docstring)."""

    #: sizes of the input and output ports, set by each block's ``__init__``
    input_sizes: dict[str, int]
    output_sizes: dict[str, int]
    #: True when ``outputs`` depends on the current inputs
    feedthrough: ClassVar[bool] = False
    #: True when the block has no state (``advance`` does nothing)
    stateless: ClassVar[bool] = False

    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def advance(self, t: float, h: float, inputs: Mapping[str, Segment]) -> None:
        raise NotImplementedError

    def get_state(self) -> dict[str, Any]:
        return copy.deepcopy(vars(self))

    def set_state(self, state: Mapping[str, Any]) -> None:
        vars(self).update(copy.deepcopy(dict(state)))
