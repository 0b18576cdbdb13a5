"""Paper 003: observer of state and sinusoidal disturbance with finite-time DREM.

* :mod:`~observers.uio.design` -- ``G``, ``M``, ``F`` of (3)-(4), relative-degree checks;
* :mod:`~observers.uio.generator` -- the known generator of ``theta``, ``e^{Gamma t}``;
* :mod:`~observers.uio.signals` -- one LTI system driven by ``y`` with linear read-outs;
* :mod:`~observers.uio.regressions` -- regressions (10), (15), (17) as read-outs;
* :mod:`~observers.uio.harmonic` -- stage 3, (20)-(23);
* :mod:`~observers.uio.identified_plant` -- stage 4, the state from the identified plant;
* :mod:`~observers.uio.settling` -- when a stage is identified;
* :mod:`~observers.uio.observer` -- the block :class:`UIOFiniteTimeObserver`.

See ``docs/paper003.md``.
"""

from .design import UIODesign, check_relative_degree, relative_degree, uio_gain, uio_matrices
from .generator import GeneratorFlow, check_generator
from .observer import UIOFiniteTimeObserver, UIOSettings, default_rates

__all__ = ["GeneratorFlow", "UIODesign", "UIOFiniteTimeObserver", "UIOSettings", "check_generator",
           "check_relative_degree", "default_rates", "relative_degree", "uio_gain", "uio_matrices"]
