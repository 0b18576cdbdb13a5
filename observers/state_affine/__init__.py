"""DREM adaptive observers for nonlinear systems reducible to a state-affine form (paper 004).

* :mod:`~observers.state_affine.model` -- the user's map to the form (2), relation (3), left inverse
* :mod:`~observers.state_affine.parametrization` -- filters of Statements 1-2, regression (4)/(5), extension (6)
* :mod:`~observers.state_affine.observer` -- mixing, finite-time gradient estimator, observer of Statement 3

Derivation, interpretations of the paper and measured numbers: ``docs/paper004.md``.
"""

from .model import StateAffineModel, Terms, require_bounded_filter
from .observer import StateAffineObserver
from .parametrization import Parametrization

__all__ = ["StateAffineModel", "Terms", "require_bounded_filter", "Parametrization", "StateAffineObserver"]
