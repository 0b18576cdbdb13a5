"""What the master needs of an instantiated FMU, whatever its FMI version (:mod:`.fmi2`, :mod:`.fmi3`).

The version is chosen once, where the FMU is opened (:func:`fmus.master.session.open_instance`, from
its modelDescription); the rest of the master sees only this interface.
"""

from __future__ import annotations

from ctypes import c_int

import numpy as np

from .errors import SimulationError, closest

__all__ = ["Instance", "fixed_function"]


class Instance:
    """An instantiated FMU with name -> value-reference maps and an output cache.

    Names are FMI 2.0 element names (``x_hat[2]``, ``u``): :attr:`variables` maps each to an object
    with ``valueReference``, ``causality`` and ``type``; :attr:`outputs` (names) and :attr:`output_vrs`
    are in the order of :attr:`output_values`.  Wiring (:func:`fmus.master.wiring.wire`) sets
    :attr:`input_vrs`, :attr:`input_sources` (each input's producer in the shared output vector) and
    :attr:`stepped_before` (that producer steps first in a Gauss-Seidel round), then calls
    :meth:`prepare`.

    The calls of the stepping loop (:meth:`set_inputs`, :meth:`do_step`, :meth:`refresh_outputs`,
    :meth:`step`) return FMI statuses; the others raise fmpy's exceptions (the master wraps them:
    :func:`fmus.master.errors.call`).
    """

    #: the binary steps in one call (set inputs, step, read outputs: :meth:`step`)
    batched = False

    def __init__(self, name: str, description, logger):
        self.name = name
        self.description = description
        self._log = logger
        self.feedthrough = any(u.dependencies for u in description.outputs)
        self.can_save_state = bool(description.coSimulation.canGetAndSetFMUstate)  # fmpy: one name for FMI 2, 3
        self.input_vrs: list[int] = []
        self.input_sources: np.ndarray = np.zeros(0, dtype=int)
        self.stepped_before: np.ndarray = np.zeros(0, dtype=bool)
        self.instantiated = False
        self.lease = None                #: the extracted folder's :class:`~fmus.master.cache.Lease`, released at close

    # ------------------------------------------------------------------ names
    def variable(self, name: str):
        try:
            return self.variables[name]
        except KeyError:
            raise SimulationError(f"{self.name}.{name}: no such variable{closest(name, self.variables)}") from None

    def port(self, name: str, causality: str) -> list[str]:
        """Element names of ``name`` (a scalar variable or a whole array port)."""
        if name in self.variables:
            names = [name]
        else:
            names = [n for n in self.variables if n.startswith(name + "[")]
            if not names:
                candidates = {n.split("[")[0] for n in self.variables if self.variables[n].causality == causality}
                raise SimulationError(f"{self.name}.{name}: no such {causality}{closest(name, candidates)}")
        for n in names:
            if self.variables[n].causality != causality:
                raise SimulationError(f"{self.name}.{n}: is a {self.variables[n].causality}, "
                                      f"expected an {causality}")
        return names

    def output_dependencies(self) -> list[set[str] | None]:
        """Per output (in :attr:`outputs` order): the input elements it depends on directly, from the
        modelDescription's ModelStructure, or None (not declared: every input, as the standard says)."""
        declared: dict[str, set[str] | None] = {}
        for unknown in self.description.outputs:
            inputs = None if unknown.dependencies is None else \
                {e for d in unknown.dependencies if d.causality == "input" for e in self._elements_of(d.name)}
            for element in self._elements_of(unknown.variable.name):
                declared[element] = inputs
        return [declared.get(output) for output in self.outputs]

    def _elements_of(self, variable: str) -> list[str]:
        """The element names of a modelDescription variable (FMI 2.0: itself; FMI 3.0 arrays: ``v[i]``)."""
        return [variable] if variable in self.variables else \
            [n for n in self.variables if n.startswith(variable + "[")]

    # ------------------------------------------------------------------ the stepping loop
    def prepare(self) -> None:
        """Buffers of the stepping loop (after wiring): input values and slopes, Gauss-Seidel indices."""
        self.input_values = np.zeros(len(self.input_vrs))
        self.input_slopes = np.zeros(len(self.input_vrs))
        self.stepped_index = np.flatnonzero(self.stepped_before)
        self.stepped_sources = self.input_sources[self.stepped_index]

    def bind_outputs(self, view: np.ndarray) -> None:
        """Make ``view`` (a slice of the shared output vector) the place :meth:`refresh_outputs` writes to."""
        self.output_values = view

    def set_value(self, name: str, value) -> None:
        """A start value, by element name."""
        raise NotImplementedError

    def set_inputs(self, derivatives: bool = False) -> int:
        """:attr:`input_values` (and, with ``derivatives``, :attr:`input_slopes` over the next step) into the FMU."""
        raise NotImplementedError

    def do_step(self, t: float, h: float) -> int:
        raise NotImplementedError

    def refresh_outputs(self) -> int:
        """Every output into :attr:`output_values`; the FMI status."""
        raise NotImplementedError

    def step(self, t: float, h: float, derivatives: bool) -> int:
        """:meth:`set_inputs`, :meth:`do_step` and :meth:`refresh_outputs` in one call (:attr:`batched` only)."""
        raise NotImplementedError

    # ------------------------------------------------------------------ life cycle
    def instantiate(self) -> None:
        """Instantiate the FMU (logging to the session's logger); sets :attr:`instantiated`."""
        raise NotImplementedError

    def setup_experiment(self, start_time: float, stop_time: float) -> None:
        raise NotImplementedError

    def enter_initialization_mode(self) -> None:
        raise NotImplementedError

    def exit_initialization_mode(self) -> None:
        raise NotImplementedError

    def terminate(self) -> None:
        raise NotImplementedError

    def reset(self) -> None:
        raise NotImplementedError

    def get_state(self):
        raise NotImplementedError

    def set_state(self, state) -> None:
        raise NotImplementedError

    def free_state(self, state) -> None:
        raise NotImplementedError

    def close(self) -> None:
        """Free the instance and unload the library (once), or only unload it if never instantiated."""
        try:
            if self.instantiated:
                self.instantiated = False
                self._free_instance()
            else:
                self._free_library()
        finally:
            if self.lease is not None:
                self.lease.release()

    def _free_instance(self) -> None:
        raise NotImplementedError

    def _free_library(self) -> None:
        raise NotImplementedError


def fixed_function(dll, name: str, argtypes):
    """The function ``name`` of ``dll`` with fixed argument types, returning an FMI status."""
    function = dll[name]          # a new function object: fmpy's own keeps its argument types
    function.argtypes, function.restype = argtypes, c_int
    return function
