"""The one generic FMI 2.0 co-simulation slave: any block becomes an FMU.

Every FMU of the project contains a two-line module (``fmus.builder.SLAVE_TEMPLATE``)::

    from obsfmu.fmus.runtime.slave import BlockSlave
    class ship_observer(BlockSlave):
        definition_file = "ship_observer.json"

and the definition file (:mod:`fmus.runtime.definition`).  :class:`BlockSlave` turns the definition
into FMI variables, builds the block from the parameter values when they are first needed, and
advances it step by step.  It is made of one part per concern, each a file of this package:

* :mod:`.variables` -- parameters, inputs (their ``<port>_interpolation`` modes and derivatives), outputs;
* :mod:`.block` -- the block of the parameters, its outputs, the start of a run;
* :mod:`.step` -- the step of an FMU: ``do_step`` and the native binary's one-call ``step_batched``, one step;
* :mod:`.state` -- FMU states: get, set, serialize;
* :mod:`.kernel` -- the image of the compiled step kernel (linear blocks step in C, issue 39);
* :mod:`.description` -- modelDescription.xml;
* :mod:`.versions` -- the numpy and scipy the FMU was built with, against the running ones;
* :mod:`.common`, :mod:`.numerics`, :mod:`.plan` -- what they share.

Inputs inside a communication step: FMI hands an FMU one input value per step, and holding it over
``[t, t + h]`` lags the signal by ``h/2``.  So every input port ``p`` of a dynamic block has an Integer
parameter ``p_interpolation``: ``0`` hold (the FMI default), ``1`` extrapolate from the previous
communication point (Jacobi masters, or a producer stepped after this FMU), ``2`` interpolate (the
value set is the one at ``t + h``: Gauss-Seidel, producer stepped before).  Input derivatives
(``fmi2SetRealInputDerivatives``, the project's master sends them) override the mode for that step.

Faults never crash the host and never corrupt the instance (docs/faults.md has the table): a call the
slave cannot carry out is *refused* (:class:`Refused`, fmi2Error, nothing changed); a step either
succeeds with a finite state or changes nothing (fmi2Discard, the fault named); anything else is a
*failure* (fmi2Error, the binary's FMI error state).
"""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

import numpy as np
from pythonfmu import Fmi2Slave
from pythonfmu.enums import Fmi2Status
from pythonfmu.default_experiment import DefaultExperiment

from obsfmu.observers.block import MAGNITUDE_BOUND, Block
from obsfmu.observers.state import Leaves

from ..definition import FmuDefinition
from .block import BlockOfParameters
from .common import InputMode, Refused, interpolation_parameter, slices
from .description import CAPABILITIES, ModelDescription
from .kernel import Kernels
from .numerics import numerics_context
from .plan import BatchPlan
from .state import FmuState, FmuStates
from . import versions
from .step import Stepping
from .variables import Variables

__all__ = ["BlockSlave", "InputMode", "FmuState", "Refused", "CAPABILITIES", "interpolation_parameter"]


class BlockSlave(Variables, BlockOfParameters, Stepping, FmuStates, Kernels, ModelDescription, Fmi2Slave):
    """Generic adapter from a :class:`~observers.block.Block` to ``pythonfmu``."""

    definition_file: ClassVar[str] = ""
    author = "obsfmu"
    license = "MIT"
    #: the exception of refused calls, found here by the native binary's bridge
    Refused: ClassVar[type] = Refused
    #: the binary's test of numbers, set on each instance by the bridge (fmus/native/bridge.c, ``native_within``):
    #: ``within`` and ``within_bound`` of observers.state in one C call, without concatenating; None in process
    native_within: ClassVar = None

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        definition = FmuDefinition.load(Path(self.resources) / self.definition_file)
        self.definition = definition
        self.modelName = definition.model_name
        self.description = definition.description
        if definition.default_experiment:
            self.default_experiment = DefaultExperiment(**definition.default_experiment)

        self._params = {p.name: np.array(p.value, dtype=float) for p in definition.parameters}
        self._input_slices = slices(definition.inputs)      # port -> its elements in the flat input vector
        self._output_slices = slices(definition.outputs)
        self._input_flat = np.zeros(sum(p.size for p in definition.inputs))
        self._inputs = {port: self._input_flat[where] for port, where in self._input_slices.items()}   # views
        self._modes = {p.name: np.zeros(1, dtype=int) for p in definition.inputs}
        self._units: dict[str, str] = {}
        self._block: Block | None = None
        self._block_error: str | None = None
        self._outputs_cache: dict[str, np.ndarray] | None = None
        self._time = 0.0
        self._stepping = False
        self._bound = MAGNITUDE_BOUND                    # the block's magnitude_bound once it exists
        self._numerics = numerics_context()              # where entry points run (numpy errors ignored)
        self._feedthrough = True                         # the block's, once it exists
        self._bad: dict[str, float] = {}                 # input (or der(input)) element -> refused value
        self._sampling_noted = False                     # the warning of a sample instant inside a step: given
        self._step_noted = False                         # the warning of a converged flag held at 0: given
        self._step_rate = 0.0                            # the block's, once it exists (slave/block.py)
        self._snapshot: tuple[dict, Leaves] | None = None   # the block's state now, checked (rollback point)
        self._last_inputs = {}                          # port -> (its value, the time it belongs to)
        self._derivatives: dict[str, np.ndarray] = {}  # first input derivatives for the next step
        self._derivative_store = {p.name: np.zeros(p.size) for p in definition.inputs}  # reused (one per port)
        self._batch: BatchPlan | None = None           # the buffers of step_batched (native binary)
        self._input_elements: dict[int, tuple[str, int, str]] = {}  # value reference -> (port, index, name)
        self._element_names = {p.name: p.element_names for p in definition.inputs}
        self._output_offsets: dict[int, int] = {}    # output value reference -> position in the flat outputs
        self._output_plans: dict[tuple, np.ndarray | None] = {}   # fmi2GetReal's vrs -> positions (None: not all outputs)
        self._flat: tuple[dict | None, np.ndarray] = (None, np.zeros(0))   # (outputs cache, its flat vector)
        self._register_variables()
        mismatch = versions.note(Path(self.resources), definition.model_name)
        if mismatch:
            self.log(mismatch, Fmi2Status.warning)
        for warning in definition.warnings:          # a failed check the file chose to build anyway
            self.log(f"built anyway (check = false): {warning}", Fmi2Status.warning)
