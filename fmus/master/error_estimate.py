"""The adaptive master's error estimate: step doubling, the order it learns, the outputs' rounding noise.

Every step of length ``h`` is also done as two steps of ``h/2`` from the same saved FMU states;
Richardson's estimate ``|y_h/2 - y_h| / (2^p - 1)`` of the error of the finer solution is measured per
unit step against ``tolerance`` (absolute for ``|y| <= 1``, relative above) on every output.  The
step-size controller (:mod:`.adaptive`) decides what to do with it; this module only estimates.

Order.  ``p`` starts at the coupling's order and is learnt from rejected steps: after a shorter try at
the same ``t``, the ratio of the differences shows the order the outputs really have.

Rounding noise.  A truncation error shrinks like ``h^(p+1)`` when the step is shortened; a difference
between the two solutions that does not even halve when the step does is rounding noise of that output
(e.g. ``F_max = 1/lambda_min(P)`` of the paper-001 observer, relative noise 1e-9), which no step length
removes.  Its level relative to the output is remembered per output (decaying by 0.1 % per accepted
step) and tolerated, instead of driving the step to its minimum for the rest of the run.  Noise does not
grow with the step, so only the outputs above their noise level say whether a doubled step would pass.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .round import Stepper

__all__ = ["Estimate", "StepDoubling"]


@dataclass
class Estimate:
    """One step of length ``h`` from ``t`` done both ways."""

    middle: np.ndarray    #: the outputs at ``t + h/2`` (the finer solution)
    fine: np.ndarray      #: the outputs at ``t + h`` (the finer solution; the stepper's live vector)
    error: float          #: the worst estimated error over its allowance (<= 1: within the tolerance)
    growth: float         #: the same over the outputs above their noise only (the doubled step's outlook)
    difference: np.ndarray  #: the estimated error per output


class StepDoubling:
    """Step doubling on a :class:`Stepper` with rollback: :meth:`attempt`, then :meth:`accept` or :meth:`reject`.

    ``order`` is the coupling's order (2 linear, 1 hold); ``tolerance`` the error per unit step over
    ``span`` (the length of the run).  The FMU states at the start of the step are saved once and kept
    across rejected attempts at the same ``t``.
    """

    def __init__(self, stepper: Stepper, order: int, tolerance: float, span: float):
        self.stepper, self.order, self.tolerance, self.span = stepper, order, tolerance, span
        self.noise = np.zeros_like(stepper.live)     # per-output rounding noise of the difference, relative
        self.p = float(order)                        # the order of the error, learnt from rejected steps
        self.tried: tuple[int, np.ndarray] | None = None  # the last rejected attempt at this t: (k, difference)
        self.saved = None                            # the FMU states at t (kept across rejected attempts)

    def attempt(self, t: float, h: float, k: int) -> Estimate:
        """The step from ``t`` of length ``h`` (``step * 2**k``) as one step and as two halves."""
        stepper = self.stepper
        if self.saved is None:
            self.saved = stepper.save()
        stepper.round(t, h)
        coarse = stepper.live.copy()
        stepper.restore(self.saved)
        stepper.round(t, h / 2)
        middle = stepper.live.copy()
        stepper.round(t + h / 2, h / 2)
        fine = stepper.live
        difference = np.abs(fine - coarse)
        magnitude = np.maximum(1.0, np.abs(fine))
        if self.tried is not None:                   # shorter than the last try at this t: did it help?
            self._learn(k, h, difference, magnitude)
        p, noise, tolerance, span = self.p, self.noise, self.tolerance, self.span
        difference = difference / (2**p - 1)
        per_step = magnitude * (tolerance * (h / span))
        error = float(np.max(difference / np.maximum(per_step, magnitude * noise))) if fine.size else 0.0
        truncation = difference > magnitude * noise       # the outputs above their rounding noise
        growth = float(np.max(difference[truncation] / per_step[truncation])) if truncation.any() else 0.0
        return Estimate(middle, fine, error, growth, difference)

    def _learn(self, k: int, h: float, difference: np.ndarray, magnitude: np.ndarray) -> None:
        """Compare with the last rejected (longer) try: outputs that stalled are noise; the others show the order."""
        tried_k, tried_difference = self.tried
        p, noise, tolerance, span = self.p, self.noise, self.tolerance, self.span
        levels = tried_k - k
        stalled = (difference / (2**p - 1) > magnitude * np.maximum(tolerance * (h / span), noise)) \
            & (difference * 2.0 ** levels > tried_difference)
        noise[stalled] = 2.0 * difference[stalled] / (2**p - 1) / magnitude[stalled]
        worst = int(np.argmax(np.where(stalled, 0.0, tried_difference)))
        if not stalled[worst] and difference[worst] > 0.0:      # the order the differences show
            observed = np.log2(tried_difference[worst] / difference[worst]) / levels - 1.0
            self.p = float(np.clip(0.5 * (p + observed), self.order, 2 * self.order + 1))

    def accept(self) -> None:
        """The attempt is taken: its saved states go, the noise levels decay."""
        self.stepper.free(self.saved)
        self.saved = None
        self.noise *= 0.999
        self.tried = None

    def reject(self, k: int, estimate: Estimate) -> None:
        """The attempt (at ``step * 2**k``) is rolled back; it is remembered for the next, shorter one."""
        self.stepper.restore(self.saved)
        self.tried = (k, estimate.difference * (2**self.p - 1))
