"""The adaptive master's step-size controller, around the error estimate of :mod:`.error_estimate`.

Gauss-Seidel steps of lengths ``step * 2**k`` (``-halvings <= k <= k_max``): a step and its halves reuse
cached discretisations inside the FMUs.  A step within the tolerance is taken and the next one doubled
when the estimate says it would pass; a step outside is rolled back and shortened by as many halvings as
the error asks for.  At the smallest step a step that still misses the tolerance is taken and counted
-- the FMUs' own integration error is then the floor -- and a warning says how many.
"""

from __future__ import annotations

import warnings

import numpy as np

from .error_estimate import StepDoubling
from .loop import Loop
from .round import Stepper

__all__ = ["adaptive"]


def adaptive(stepper: Stepper, start_time: float, stop_time: float, step: float, tolerance: float, order: int,
             loop: Loop, halvings: int = 12) -> None:
    """The adaptive run from ``start_time`` to ``stop_time``, initial step ``step``; ``order`` is the
    coupling's (2 linear, 1 hold).  Both points of every taken step (``t + h/2``, ``t + h``) are recorded."""
    span = stop_time - start_time
    t, k, k_max = start_time, 0, int(np.floor(np.log2(span / 10 / step))) if span / 10 > step else 0
    forced = 0
    estimator = StepDoubling(stepper, order, tolerance, span)
    if stepper.linear:
        stepper.probe_initial_slopes(t, step * 2.0**-20)
    while stop_time - t > 1e-12 * span:
        h = min(step * 2.0**k, stop_time - t)
        estimate = estimator.attempt(t, h, k)
        if estimate.error <= 1.0 or k <= -halvings:
            forced += estimate.error > 1.0
            loop.record(t + h / 2, estimate.middle)
            loop.record(t + h, estimate.fine)
            t += h
            estimator.accept()
            if estimate.growth < 0.5**(estimator.p + 1):     # the doubled step is expected to pass
                k = min(k + 1, k_max)
            if not loop.accepted(t):
                break
        else:
            estimator.reject(k, estimate)
            k = max(k - max(1, int(np.ceil(np.log2(estimate.error) / estimator.p))), -halvings)
    if forced:
        warnings.warn(f"adaptive master: {forced} of {loop.steps} steps at the smallest step "
                      f"({step * 2.0**-halvings:.3g}) missed the tolerance {tolerance:g}", RuntimeWarning, stacklevel=3)
