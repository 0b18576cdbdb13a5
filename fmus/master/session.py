"""Runs of a :class:`System`: a :class:`Session` opens its FMUs once and runs them as often as needed;
:func:`cosimulate` is one run of a fresh session.

Orders (:data:`ORDERS`): ``gauss-seidel`` and ``jacobi`` (fixed steps, :mod:`.loop`; the round:
:mod:`.round`), ``adaptive`` (Gauss-Seidel steps under error control, :mod:`.adaptive`).  Couplings
(:data:`COUPLINGS`): ``linear`` (inputs on straight lines over the step, through the FMI input
derivatives) or ``hold`` (the plain FMI zero-order hold, first order instead of second).
Every output of every instance is recorded at every communication point, ``t0`` included, by a
:class:`~fmus.master.recorder.Recorder` (default: :class:`~fmus.master.recorder.MemoryRecorder`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from fmpy import read_model_description

from .adaptive import adaptive
from .cache import leased
from .errors import SimulationError, call, check, closest
from .fmi2 import Fmi2Instance
from .fmi3 import Fmi3Instance
from .instance import Instance
from .log import Logger
from .loop import Loop, Progress, fixed
from .recorder import MemoryRecorder, Recorder
from .round import Stepper
from .system import Component, System
from .wiring import unconnected_inputs, wire

__all__ = ["Session", "cosimulate", "open_instance", "ORDERS", "COUPLINGS"]

ORDERS = ("gauss-seidel", "jacobi", "adaptive")
#: most communication points of a fixed-step run (1e9 steps of a few microseconds: hours), checked before it starts
MAX_POINTS = 1e9
COUPLINGS = ("linear", "hold")


def open_instance(component: Component, logger: Logger) -> Instance:
    """The FMU of ``component``, extracted once per content (:mod:`.cache`), as an instance of the FMI
    version its modelDescription declares (:class:`~.fmi2.Fmi2Instance`, :class:`~.fmi3.Fmi3Instance`)."""
    fmu = Path(component.fmu)
    if not fmu.is_file():
        raise SimulationError(f"{component.name}: FMU file {fmu} does not exist (run 'obsfmu build')")
    folder, lease = leased(fmu)          # first: the archive is checked before anything of it is read
    try:
        description = read_model_description(str(folder))
        if description.coSimulation is None:
            raise SimulationError(f"{component.name}: {fmu} is not a co-simulation FMU")
        implementation = Fmi3Instance if description.fmiVersion.startswith("3") else Fmi2Instance
        instance = implementation(component.name, description, folder, logger)
    except BaseException:
        lease.release()
        raise
    instance.lease = lease               # fmi2Reset reads the folder again: held until the instance closes
    return instance


def component_of(system: System, name: str) -> Component:
    return next(c for c in system.components if c.name == name)


def check_run_settings(stop_time, step, order, start_time, coupling, tolerance) -> None:
    """A :class:`SimulationError` naming the first bad setting of a run."""
    if order not in ORDERS:
        raise SimulationError(f"order: {order!r} is not one of {ORDERS}")
    if coupling not in COUPLINGS:
        raise SimulationError(f"coupling: {coupling!r} is not one of {COUPLINGS}")
    if not (np.isfinite(step) and step > 0):
        raise SimulationError(f"step: must be a positive number, got {step!r}")
    if not (np.isfinite(tolerance) and tolerance > 0):
        raise SimulationError(f"tolerance: must be a positive number, got {tolerance!r}")
    if not (np.isfinite(start_time) and np.isfinite(stop_time)):
        raise SimulationError(f"start_time, stop_time: must be finite, got {start_time!r}, {stop_time!r}")
    if not stop_time > start_time:
        raise SimulationError(f"stop_time: must be after start_time {start_time}, got {stop_time}")
    points = (stop_time - start_time) / step
    if order != "adaptive" and not points <= MAX_POINTS:
        raise SimulationError(f"step: {step:g} from {start_time:g} to stop_time {stop_time:g} is {points:.3g} "
                              f"communication points, more than the limit of {MAX_POINTS:.0e} (a longer step or a "
                              f"shorter run)")


def _require_inputs(missing: list[str]) -> None:
    """An input nobody connected silently reads its start value (0): an error naming it, unless the
    caller gave that value explicitly (``Component(..., start={"u": 0.0})``)."""
    if missing:
        more = f" (and {len(missing) - 1} more: {', '.join(missing[1:4])}{', ...' if len(missing) > 4 else ''})" \
            if len(missing) > 1 else ""
        name = missing[0].partition(".")[2]
        raise SimulationError(f"{missing[0]} is not connected: connect it or give it a start value "
                              f"(Component(..., start={{{name!r}: value}}), --set, or [values] in a system file)"
                              + more)


class Session:
    """The FMUs of ``system`` extracted and instantiated once, run as often as needed.

    Use it as a context manager (or call :meth:`close`)::

        with Session(system) as session:
            first = session.run(10.0, 1e-3)
            second = session.run(10.0, 1e-3, start={"plant": {"x0[1]": 0.5}})

    Every run after the first resets the instances (``fmi2Reset``) and sets
    the components' start values, then ``start`` (per-run overrides) on top.
    """

    def __init__(self, system: System, echo_log: bool = True):
        names = [c.name for c in system.components]
        if len(set(names)) != len(names):
            raise SimulationError(f"components: instance names must be unique, got {names}")
        self.system = system
        self.logger = Logger(echo_log)
        self.instances: dict[str, Instance] = {}
        self._fresh = True
        try:
            for component in system.components:
                self.instances[component.name] = open_instance(component, self.logger)
            connected = wire(self.instances, system.connections)
            _require_inputs(unconnected_inputs(self.instances, connected,
                                               {c.name: c.start for c in system.components}))
            for inst in self.instances.values():       # a refusal (e.g. another GUID) names the FMU, no traceback
                call(inst, self.logger, f"instantiating {component_of(system, inst.name).fmu}", inst.instantiate)
        except BaseException:
            self.close()
            raise
        self.columns = [f"{inst.name}.{out}" for inst in self.instances.values() for out in inst.outputs]

    def __enter__(self) -> "Session":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Free the instances (idempotent); the extracted FMUs stay in the cache (:mod:`.cache`)."""
        for inst in self.instances.values():
            try:
                inst.close()
            except Exception:
                pass
        self.instances = {}

    def run(self, stop_time: float, step: float, order: str = "gauss-seidel", start_time: float = 0.0,
            coupling: str = "linear", progress: bool = False, tolerance: float = 1e-6,
            start: dict[str, dict[str, float]] | None = None, recorder: Recorder | None = None,
            should_stop=None, time_unit: str = "s", ramp: int = 0):
        """One run from ``start_time`` to ``stop_time``; see :func:`cosimulate` for the parameters.

        ``start`` maps instance names to extra start values for this run only.
        ``recorder`` receives every communication point (default: a
        :class:`MemoryRecorder`; its :meth:`~Recorder.result` is returned).
        ``should_stop()`` is asked after every communication point; when it
        returns true the run ends there (the recorder has every point so far)
        and the result's ``interrupted`` attribute is set when it has one.
        """
        check_run_settings(stop_time, step, order, start_time, coupling, tolerance)
        if not self.instances:
            raise SimulationError("session: already closed")
        start = start or {}
        for name in start:
            if name not in self.instances:
                raise SimulationError(f"start: unknown instance {name!r}{closest(name, self.instances)}")
        if order == "adaptive":
            unable = [inst.name for inst in self.instances.values() if not inst.can_save_state]
            if unable:
                raise SimulationError(f"order 'adaptive' rolls steps back, but {unable} cannot get/set their state")
        if not self._fresh:
            for inst in self.instances.values():
                call(inst, self.logger, "reset", inst.reset)
        self._fresh = False
        recorder = recorder or MemoryRecorder()
        recorder.begin(self.columns)
        stepper = Stepper(self.instances, self.logger, jacobi=order == "jacobi", linear=coupling == "linear")
        starts = {c.name: {**c.start, **start.get(c.name, {})} for c in self.system.components}
        _initialize(self.instances, starts, stepper, start_time, stop_time, self.logger)
        loop = Loop(recorder, should_stop, Progress(progress, start_time, stop_time, time_unit))
        loop.record(start_time, stepper.live)
        if order == "adaptive":
            adaptive(stepper, start_time, stop_time, step, tolerance, 2 if coupling == "linear" else 1, loop)
        else:
            fixed(stepper, start_time, stop_time, step, loop, ramp)
        loop.progress.close(loop.steps)
        if not loop.interrupted:
            for inst in self.instances.values():
                call(inst, self.logger, "terminate", inst.terminate)
        result = recorder.result()
        if stepper.loops is not None:
            self.logger.note(stepper.loops.report())
        if loop.interrupted and hasattr(result, "interrupted"):
            result.interrupted = True
        return result


def cosimulate(system: System, stop_time: float, step: float, order: str = "gauss-seidel",
               start_time: float = 0.0, coupling: str = "linear", progress: bool = False,
               echo_log: bool = True, tolerance: float = 1e-6, recorder: Recorder | None = None,
               should_stop=None, time_unit: str = "s", ramp: int = 0):
    """Run ``system`` once from ``start_time`` to ``stop_time`` (a fresh :class:`Session`).

    Parameters
    ----------
    step : float
        Communication step; the initial step of the adaptive master.
    order : {"gauss-seidel", "jacobi", "adaptive"}
        Stepping order; Gauss-Seidel follows the order of ``system.components``.
    coupling : {"linear", "hold"}
        How inputs vary inside a step (see the module docstring).
    tolerance : float
        Error per unit step requested from the adaptive master.
    progress : bool
        Show a progress bar on stderr when the run takes longer than a second.
    recorder : Recorder, optional
        Receives every communication point (default: in memory).
    should_stop : callable, optional
        Asked after every communication point; true ends the run there.
    time_unit : str
        Unit of the models' time, for the progress bar.
    ramp : int
        Fixed-step orders: split the first step into ``h/2^ramp, h/2^ramp, h/2^(ramp-1), ..., h/2``
        (every point recorded; the grid ``start_time + k step`` is kept).  The linear coupling has
        no history on the first step, and blocks that rebuild their inputs from past samples
        (:class:`observers.ltv.stepping.PolynomialInputs`) need a few: their start-up error,
        which otherwise sets the accuracy of the whole run, shrinks with the first steps.

    Returns
    -------
    Result
        ``time`` and every output of every instance (``instance.variable``) at
        every communication point (or what ``recorder.result()`` returns).
    """
    check_run_settings(stop_time, step, order, start_time, coupling, tolerance)
    with Session(system, echo_log=echo_log) as session:
        return session.run(stop_time, step, order=order, start_time=start_time, coupling=coupling,
                           progress=progress, tolerance=tolerance, recorder=recorder,
                           should_stop=should_stop, time_unit=time_unit, ramp=ramp)


def _initialize(instances: dict[str, Instance], starts: dict[str, dict[str, float]], stepper: Stepper,
                start_time, stop_time, logger: Logger) -> None:
    for inst in instances.values():
        call(inst, logger, "setupExperiment", inst.setup_experiment, start_time, stop_time)
        call(inst, logger, "enterInitializationMode", inst.enter_initialization_mode)
    for name, values in starts.items():
        inst = instances[name]
        for variable, value in values.items():
            inst.variable(variable)
            call(inst, logger, f"setting {variable}={value}", inst.set_value, variable, value)
    stepper.settle(len(instances) + 1)
    for inst in instances.values():
        call(inst, logger, "exitInitializationMode", inst.exit_initialization_mode)
        check(inst, logger, "reading outputs", inst.refresh_outputs())
    stepper.solve_loops(start_time)
    if not np.all(np.isfinite(stepper.live)):
        bad = [inst.name for inst in instances.values() if not np.all(np.isfinite(inst.output_values))]
        raise SimulationError(f"initial outputs of {bad} are not finite; FMU says: "
                              + " ; ".join(logger.last(b) for b in bad))
    stepper.mark_communication_point()
