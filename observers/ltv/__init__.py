"""Paper 001: adaptive observer of a nonlinear LTV plant with unknown constant parameters.

* :mod:`~observers.ltv.stepping` -- user-function checks, polynomial inputs inside a step, RK4 with
  dense output, the resolved fast part of ``y`` (shared with the plant, :mod:`plants.ltv`)
* :mod:`~observers.ltv.observer` -- filters (2)-(6), regression (7), least squares, estimate (10)

See ``docs/paper001.md``.
"""

from .observer import LTVAdaptiveObserver

__all__ = ["LTVAdaptiveObserver"]
