"""Discrete adaptive observer of paper 000 (GPEBO + DREM) for plants driven by linear generators.

* :mod:`~observers.gpebo.model` -- the plant class (1)-(2): shift matrix, generators, ``D(u, y)``
* :mod:`~observers.gpebo.regression` -- the derived input-output regression (16) of the example, and of
  any plant of the class with one unknown coefficient per generator (terms of (8): :mod:`~observers.gpebo.terms`)
* :mod:`~observers.gpebo.companion` -- the regression (16) with whole unknown gamma vectors
  (:mod:`~observers.gpebo.laurent`: the polynomials it is built with)
* :mod:`~observers.gpebo.filters` -- the GPEBO filters of Statement 1
* :mod:`~observers.gpebo.observer` -- the three steps as a block

Derivation and measurements: ``docs/paper000.md``.
"""

from .filters import GpeboFilters
from .model import GeneratorModel, generator_matrix, require_sample_step, shift_matrix
from .observer import GpeboObserver
from .regression import ExampleRegression

__all__ = ["GeneratorModel", "generator_matrix", "shift_matrix", "require_sample_step", "ExampleRegression",
           "GpeboFilters", "GpeboObserver"]
