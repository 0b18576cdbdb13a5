"""FMI 2.0 FMUs in the master: :class:`Fmi2Instance` on fmpy's ``FMU2Slave``.

fmpy loads the FMU and makes every call outside the stepping loop.  Inside it, the calls of a
communication step (``fmi2SetReal``, ``fmi2SetRealInputDerivatives``, ``fmi2DoStep``, ``fmi2GetReal``) go
straight to the binary through ctypes functions with fixed argument types, on numpy buffers allocated
once per run: the FMU writes its outputs directly into the shared output vector (fmpy's wrappers cost
3-9 us per call, a direct call 0.1 us plus what the FMU does).  An obsfmu FMU does the four in one call
(``obsfmuDoStepPlanned``, :meth:`Fmi2Instance.step`).
"""

from __future__ import annotations

from ctypes import PYFUNCTYPE, Structure, addressof, c_double, c_int, c_size_t, c_void_p

import numpy as np
from fmpy.fmi2 import FMU2Slave

from .errors import WARNING, SimulationError
from .instance import Instance, fixed_function

__all__ = ["Fmi2Instance"]


class StepPlan(Structure):
    """``ObsfmuStepPlan`` (fmus/native/loader.c): the arrays of one-call steps, built once per run."""
    _fields_ = [("vr", c_void_p), ("nvr", c_size_t), ("value", c_void_p), ("slope", c_void_p),
                ("output_vr", c_void_p), ("n_outputs", c_size_t), ("output", c_void_p)]


class _RawCalls:
    """The FMI functions of the stepping loop, called on the binary directly (fixed argument types)."""

    def __init__(self, dll):
        pointer, size = c_void_p, c_size_t
        self.set_real = fixed_function(dll, "fmi2SetReal", [pointer, pointer, size, pointer])
        self.set_derivatives = fixed_function(dll, "fmi2SetRealInputDerivatives",
                                              [pointer, pointer, size, pointer, pointer])
        self.do_step = fixed_function(dll, "fmi2DoStep", [pointer, c_double, c_double, c_int])
        self.get_real = fixed_function(dll, "fmi2GetReal", [pointer, pointer, size, pointer])
        # an obsfmu binary: its one-call step with its arrays in a plan (fmus/native/loader.c), called with the
        # GIL held -- the step runs Python code (the slave) that would take it back at once
        prototype = PYFUNCTYPE(c_int, pointer, c_double, c_double, pointer)
        self.step_planned = prototype(("obsfmuDoStepPlanned", dll)) if hasattr(dll, "obsfmuDoStepPlanned") else None


class Fmi2Instance(Instance):
    """An instantiated FMI 2.0 FMU (``slave``: fmpy's ``FMU2Slave``)."""

    def __init__(self, name: str, description, directory, logger):
        super().__init__(name, description, logger)
        self.variables = {v.name: v for v in description.modelVariables}
        self.outputs = [v.name for v in description.modelVariables if v.causality == "output"]
        self.output_vrs = [self.variables[n].valueReference for n in self.outputs]
        self.can_interpolate = bool(description.coSimulation.canInterpolateInputs)
        self.slave = FMU2Slave(guid=description.guid, unzipDirectory=str(directory),
                               modelIdentifier=description.coSimulation.modelIdentifier, instanceName=name)
        self.output_values = np.zeros(len(self.outputs))
        self.raw = _RawCalls(self.slave.dll)
        self._bind_life_cycle()

    def prepare(self) -> None:
        """Buffers of the stepping loop (after wiring): value references, input values and slopes."""
        super().prepare()
        self._input_vr = np.array(self.input_vrs, dtype=np.uint32)
        self._output_vr = np.array(self.output_vrs, dtype=np.uint32)
        self._orders = np.ones(len(self.input_vrs), dtype=np.int32)
        self._pointers = (self._input_vr.ctypes.data, self._output_vr.ctypes.data, self._orders.ctypes.data,
                          self.input_values.ctypes.data, self.input_slopes.ctypes.data)

    def bind_outputs(self, view: np.ndarray) -> None:
        """Make ``view`` (a slice of the shared output vector) the place ``fmi2GetReal`` writes to."""
        self.output_values = view
        self._output_address = view.ctypes.data
        vr, outputs, _, values, slopes = self._pointers    # step's plans, without and with slopes
        slopes = slopes if self.can_interpolate else None
        self._plans = tuple(StepPlan(vr, len(self.input_vrs), values, slope, outputs, len(self.output_vrs),
                                     self._output_address) for slope in (None, slopes))
        self._plan_addresses = tuple(addressof(plan) for plan in self._plans)

    def set_value(self, name: str, value) -> None:
        variable = self.variable(name)
        vr = [variable.valueReference]
        if variable.type == "Real":
            self.slave.setReal(vr, [float(value)])
        elif variable.type in ("Integer", "Enumeration"):
            if float(value) != int(float(value)):
                raise SimulationError(f"{self.name}.{name}: expects an integer, got {value!r}")
            self.slave.setInteger(vr, [int(float(value))])
        elif variable.type == "Boolean":
            self.slave.setBoolean(vr, [str(value).lower() in ("1", "true")])
        else:
            raise SimulationError(f"{self.name}.{name}: type {variable.type} cannot be set")

    def refresh_outputs(self) -> int:
        """``fmi2GetReal`` of every output into :attr:`output_values`; the FMI status."""
        if not self.output_vrs:
            return 0
        return self.raw.get_real(self.slave.component, self._pointers[1], len(self.output_vrs),
                                 self._output_address)

    def set_inputs(self, derivatives: bool = False) -> int:
        """``fmi2SetReal`` of :attr:`input_values` (and, with ``derivatives``, ``fmi2SetRealInputDerivatives``
        of :attr:`input_slopes`); the worst FMI status."""
        count = len(self.input_vrs)
        if not count:
            return 0
        vr, _, orders, values, slopes = self._pointers
        status = self.raw.set_real(self.slave.component, vr, count, values)
        if derivatives and self.can_interpolate and status <= WARNING:
            status = max(status, self.raw.set_derivatives(self.slave.component, vr, count, orders, slopes))
        return status

    def do_step(self, t: float, h: float) -> int:
        return self.raw.do_step(self.slave.component, t, h, 1)

    def step(self, t: float, h: float, derivatives: bool) -> int:
        """:meth:`set_inputs`, :meth:`do_step` and :meth:`refresh_outputs` in one call of the binary
        (``obsfmuDoStepPlanned``, project FMUs only: :attr:`batched`); the FMI status."""
        return self.raw.step_planned(self.slave.component, t, h, self._plan_addresses[derivatives])

    def plan_address(self, derivatives: bool) -> int:
        """The address of the plan of :meth:`step` (``ObsfmuStepPlan``), for the round in one call."""
        return self._plan_addresses[derivatives]

    @property
    def batched(self) -> bool:
        """The binary offers ``obsfmuDoStepPlanned`` (an obsfmu FMU, fmus/native/loader.c)."""
        return self.raw.step_planned is not None

    # ------------------------------------------------------------------ life cycle (fmpy's FMU2Slave)
    def instantiate(self) -> None:
        self.slave.instantiate(callbacks=self._log.callbacks, loggingOn=True)
        self.instantiated = True

    def setup_experiment(self, start_time: float, stop_time: float) -> None:
        self.slave.setupExperiment(None, start_time, stop_time)

    def _bind_life_cycle(self) -> None:
        """The calls of the interface that are fmpy's own, one to one."""
        slave = self.slave
        self.enter_initialization_mode, self.exit_initialization_mode = (slave.enterInitializationMode,
                                                                         slave.exitInitializationMode)
        self.terminate, self.reset = slave.terminate, slave.reset
        self.get_state, self.set_state, self.free_state = slave.getFMUstate, slave.setFMUstate, slave.freeFMUstate
        self._free_instance = slave.freeInstance       # and unloads the library (fmpy), once
        self._free_library = slave.freeLibrary
