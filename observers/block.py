"""The interface every simulated object (plant, observer, controller) offers.

A *block* is a causal dynamic system advanced over communication steps.  It
is plain Python/numpy, usable without FMI; the FMU adapter in
``fmus/runtime/slave`` wraps any block generically.

* ``outputs(t, inputs)`` returns the outputs at the current time ``t`` as a
  dict of 1-D arrays.  A block whose outputs depend on its current inputs
  (direct feedthrough, e.g. ``u = -K x_hat + r``) sets ``feedthrough = True``.
* ``advance(t, h, inputs)`` moves the state from ``t`` to ``t + h``.  Each
  input is a :class:`Segment`: the value at ``t`` plus a slope, so a block
  can integrate a linearly interpolated input exactly instead of holding it.
* ``get_state()`` / ``set_state()`` save and restore the complete state as plain data
  (:mod:`observers.state`: FMU state save/restore, rollback of a refused step).  A block
  does not write them; it declares what is *not* state in ``not_state`` (built from the
  parameters, never changed by ``advance``: models, user functions, propagators) and the
  attributes that may be ``None`` in ``state_optional``.

Rule every block follows: ``advance`` computes the new state completely and then *rebinds*
its attributes (``self.x = x_next``); it never writes into a state array (``self.x[0] = ...``,
``self.x += ...``).  A saved state then shares the arrays instead of copying them, and the
FMU layer rolls a refused step back at the cost of one walk over the attributes.

Inputs and outputs are named ports; their sizes are fixed at construction.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Mapping

import numpy as np

from .state import capture, restore

__all__ = ["Segment", "Block", "MAGNITUDE_BOUND"]

#: default bound on the magnitude of inputs, outputs, state and parameters inside an FMU
MAGNITUDE_BOUND = 1e100


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
    #: bound on the magnitude of every input, output and state value (Euclidean norm of a port
    #: or state array); the FMU layer refuses steps that would leave it
    magnitude_bound: ClassVar[float] = MAGNITUDE_BOUND
    #: attributes that are not state (see module docstring); merged along the class hierarchy
    not_state: ClassVar[tuple[str, ...]] = ("input_sizes", "output_sizes", "feedthrough", "caller_rolls_back")
    #: attributes that may be None: name -> None (plain data) or a method giving a blank object
    state_optional: ClassVar[dict[str, str | None]] = {}
    #: True when whoever calls ``advance`` puts the state back itself if it raises (the FMU slave
    #: rolls every refused step back, docs/faults.md); :meth:`atomically` then saves nothing
    caller_rolls_back: bool = False

    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def advance(self, t: float, h: float, inputs: Mapping[str, Segment]) -> None:
        raise NotImplementedError

    def atomically(self, step, *args) -> None:
        """``step(*args)`` with the state left as it was if it raises: saved before and put back here,
        unless the caller does that itself (``caller_rolls_back``), which spares a capture per step."""
        if self.caller_rolls_back:
            step(*args)
            return
        saved = self.get_state()
        try:
            step(*args)
        except Exception:
            self.set_state(saved, check=False)
            raise

    def get_state(self) -> dict[str, Any]:
        """The complete state as plain data (arrays shared with the block, see module docstring)."""
        return capture(self)

    def set_state(self, state: Mapping[str, Any], check: bool = True) -> None:
        """Restore a state of :meth:`get_state`; with ``check`` a state that does not fit this block
        raises :class:`~observers.state.StateError` and changes nothing."""
        restore(self, state, check)
