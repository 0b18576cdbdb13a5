"""Discrete blocks at any communication step: the sample clock (:class:`SampledBlock`).

A discrete block (sample time ``T``) is updated at the sample instants ``t_k = k T``::

    x[k+1] = f(t_k, x[k], u(t_k)),     x[k] held on [t_k, t_(k+1))

as a discrete block of Simulink or Modelica samples: at ``t = k T`` whatever the solver's step.  A
communication step ``[t, t + h)`` may contain no instant, one, or several:

* the inputs are *latched* at each instant the step contains, from the step's input line
  (``Segment.at(t_k - t)``: the value at ``t`` when ``t_k = t``);
* the update of instant ``t_k`` is applied when the step reaches ``t_(k+1)`` -- inside the step when the
  next instant is in it, at its end when it ends there, or in a later step;
* the latched inputs, their instant and whether their update is still due are state (:attr:`latched`,
  :attr:`latched_at`, :attr:`pending`): an FMU state taken between two instants restores the pending
  update.

With ``h = T`` (one sample per step, the blocks' DefaultExperiment) and ``h = n T`` this is exactly the
former sample loop.  Sampling is exact when every instant is a communication point (``T`` a whole
number of steps); an instant strictly inside a step takes its inputs from the step's line
(interpolated, extrapolated or held, as the coupling gives them) -- for a discrete producer, whose
output jumps at its own instants, that may be the value before or after the jump:
:attr:`SampledBlock.inexact_instant` says so once (the FMU logs it as a warning).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from .block import Block, Segment
from .integrators import DEFAULT_SUBSTEP_BUDGET, BudgetError

__all__ = ["SampledBlock", "sample_instants"]

#: instants closer than this fraction of T to a step's end belong to the next step (round-off of k T)
_SNAP = 1e-9


def sample_instants(t: float, h: float, T: float, budget: int) -> list[float]:
    """The sample instants ``k T`` in ``[t, t + h)`` (those within ``1e-9 T`` of ``t + h`` excluded).

    :class:`~observers.integrators.BudgetError` naming ``substep_budget`` before any work when there are
    more than ``budget``."""
    first = math.ceil(t / T - _SNAP)
    last = math.ceil((t + h) / T - _SNAP) - 1            # the last k with k T < t + h - 1e-9 T
    count = last - first + 1 if math.isfinite(h) else math.inf
    if count > budget:
        raise BudgetError(f"substep_budget: the step h = {h:g} contains {count:.3g} samples of T = {T:g}, more "
                          f"than substep_budget = {budget}")
    return [k * T for k in range(first, last + 1)]


class SampledBlock(Block):
    """A block updated at the instants ``k T`` (module docstring).  A subclass gives :meth:`sample_period`,
    :meth:`sample` (one update ``x[k] -> x[k+1]`` from the latched inputs) and calls
    :meth:`_init_sampling` in its constructor; :meth:`advance` is this class's."""

    not_state = ("substep_budget", "_sampled_ports", "inexact_instant")
    #: set (to the instant) when an instant fell strictly inside a communication step; the FMU logs it once
    inexact_instant: float | None = None
    #: most sample instants one communication step may contain (a subclass may make it a parameter)
    substep_budget: int = DEFAULT_SUBSTEP_BUDGET

    def _init_sampling(self, ports: Mapping[str, int]) -> None:
        """``ports``: the inputs to latch, with their sizes (in this order in :attr:`latched`)."""
        self._sampled_ports = dict(ports)
        self.latched = np.zeros(sum(self._sampled_ports.values()))
        self.latched_at = 0.0                 #: the instant the inputs were latched at
        self.pending = False                  #: its update is still due

    def sample_period(self) -> float:
        raise NotImplementedError

    def sample(self, t_k: float, inputs: Mapping[str, np.ndarray]) -> None:
        """One update at the instant ``t_k`` from the inputs latched there (rebinds the state)."""
        raise NotImplementedError

    def advance(self, t: float, h: float, inputs: Mapping[str, Segment]) -> None:
        T = self.sample_period()
        instants = sample_instants(t, h, T, self.substep_budget)
        for t_k in instants:
            self._due(t_k, T)
            if t_k > t + _SNAP * T and self.inexact_instant is None:
                self.inexact_instant = t_k
            self.latched = np.concatenate([np.atleast_1d(inputs[port].at(t_k - t)) for port in self._sampled_ports]) \
                if self._sampled_ports else self.latched
            self.latched_at, self.pending = t_k, True
        self._due(t + h, T)

    def _due(self, now: float, T: float) -> None:
        """Apply the pending update if its time (the instant after the latched one) has come by ``now``."""
        if self.pending and self.latched_at + T <= now + _SNAP * T:
            self.sample(self.latched_at, self._unpacked())
            self.pending = False

    def _unpacked(self) -> dict[str, np.ndarray]:
        values, offset = {}, 0
        for port, size in self._sampled_ports.items():
            values[port] = self.latched[offset:offset + size]
            offset += size
        return values
