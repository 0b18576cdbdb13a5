"""Deterministic signal sources: constant, step, ramp, sine, multi-sine, chirp, square, PRBS, table, CSV.

Each source is a stateless :class:`~observers.block.Block` without inputs and with one output
``y`` (size 1): ``y(t) = value(t)``.  Each also offers ``derivative(t)``, the exact time
derivative where the signal is smooth -- a master sends it as the input derivative, so linear
coupling of a smooth source stays exact.  At a discontinuity (step time, square edge, PRBS bit
boundary, table break point) ``derivative`` is the one-sided derivative from the right, and
``value`` is right-continuous: the value at a switching time is the value after it.

Frequencies are in hertz everywhere (the parameters say so: ``frequency_hz``, ``f0_hz``), phases
in radians.  ``value`` and ``derivative`` accept a float or an array of times.

Interval boundaries (square edges, PRBS bits, noise samples) are found with
:func:`interval_index`, which counts a time within ``1e-9`` of an interval of a boundary as on
it, so ``t = k * dt`` computed in floating point lands on interval ``k``.

Modules: :mod:`.base` (the :class:`Source` block), :mod:`.waveforms`, :mod:`.prbs`, :mod:`.tables`.
"""

from .base import BOUNDARY_TOLERANCE, PiecewiseConstant, Source, interval_index
from .prbs import PRBS, PRIMITIVE_TAPS
from .tables import CsvColumn, Table
from .waveforms import Chirp, Constant, MultiSine, Ramp, Sine, Square, Step

__all__ = ["BOUNDARY_TOLERANCE", "interval_index", "Source", "PiecewiseConstant", "Constant", "Step", "Ramp",
           "MultiSine", "Sine", "Chirp", "Square", "PRBS", "PRIMITIVE_TAPS", "Table", "CsvColumn"]
