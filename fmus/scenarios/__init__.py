"""Scenarios: the papers' examples as co-simulations of FMUs.

A :class:`Scenario` lists the FMUs it needs (as definitions, built on
demand into the build directory), the instances and connections, and the
defaults a user should not have to know: stop time, communication step,
order and coupling -- each chosen against the scenario's monolithic
reference and documented in its module.  :func:`run` builds what is
missing, applies ``--set`` overrides and co-simulates.
"""

from __future__ import annotations

import difflib
import math
import re
import sys
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import fmpy
from fmpy import read_model_description

from .. import native
from ..builder import build_fmu, platforms_of, why_not_current
from ..fmi3 import build_folder
from ..fmi3.elements import scalar_variables
from ..runtime.definition import FmuDefinition, experiment
from ..master import Component, Connection, Recorder, Session, SimulationError, System
from ..result import Result, RunInfo

if TYPE_CHECKING:
    from ..campaign.measures import Measure

__all__ = ["Scenario", "Summary", "SCENARIOS", "get", "add", "is_added", "ensure_fmus", "ensure_all", "ensure_definitions", "run", "run_info",
           "parse_overrides", "system", "changed_parameters", "check_step"]


@dataclass
class Summary:
    """What ``obsfmu run`` prints: a few lines of text and the numbers behind them."""

    lines: list[str]
    metrics: dict[str, float] = field(default_factory=dict)
    #: one sentence: the agreement with the independent monolithic reference, or why none applies
    reference: str = ""

    def __str__(self) -> str:
        return "\n".join(self.lines + ([self.reference] if self.reference else []))


@dataclass
class Scenario:
    name: str
    description: str
    #: FMUs the scenario needs: definitions, or (definition, extra_modules) pairs
    definitions: Callable[[], list]
    #: (instance name, model name, start values)
    components: list[tuple[str, str, dict[str, float]]]
    connections: list[Connection]
    stop_time: float
    step: float
    order: str = "gauss-seidel"
    coupling: str = "linear"
    summarize: Callable[[Result], Summary] | None = None
    #: ``plot(result, path)`` writes the figure to ``path`` and as vector graphics beside it
    plot: Callable[[Result, Path], list[Path]] | None = None
    time_unit: str = "s"  #: the unit of time of the models (``h`` for the chemostat)
    #: spacing of the rows that ``obsfmu all`` writes to CSV (None: every communication point)
    output_interval: float | None = None
    #: why the adaptive master cannot run this scenario (it is then refused at once), or None
    not_adaptive: str | None = None
    #: ``(smallest tolerance, why)``: the adaptive master refuses tighter tolerances at once, with the reason
    adaptive_floor: tuple[float, str] | None = None
    #: the adaptive master's error per unit step when none is given (``--tol``)
    tolerance: float = 1e-6
    #: the first step split into h/2^ramp, ..., h/2 (see :func:`fmus.master.cosimulate`)
    ramp: int = 0
    #: what the paper claims for this example, in our words and numbers (for ``obsfmu report``)
    claim: str = ""
    #: what ``obsfmu sweep`` measures of a sample (the scenario's ``measures.py``), or None: give the metrics
    measure: Measure | None = None
    #: the system file that defines it (``obsfmu show SCENARIO`` prints it), or None
    system_file: Path | None = None
    #: ``(|lambda|, what)``: the fastest rate of its dynamics and signals (a system file's), or None
    fastest: tuple[float, str] | None = None


def _registry() -> dict[str, Scenario]:
    """Every sub-package of this package that defines ``SCENARIO`` (or ``SCENARIOS``).

    A sub-package without either holds what several scenarios share (``ltv_common``,
    ``state_affine_common``) and is no scenario.
    """
    import importlib
    import pkgutil

    found: dict[str, Scenario] = {}
    for module_info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{__name__}.{module_info.name}")
        for scenario in getattr(module, "SCENARIOS", [getattr(module, "SCENARIO", None)]):
            if scenario is not None:
                if scenario.name in found:
                    raise RuntimeError(f"scenario {scenario.name!r} defined twice")
                found[scenario.name] = scenario
    return found


def get(name: str) -> Scenario:
    """The scenario ``name``, or one :func:`add` ed under ``name`` in this process (a system file's)."""
    try:
        return SCENARIOS[name] if name in SCENARIOS else _ADDED[name]
    except KeyError:
        raise SimulationError(f"unknown scenario {name!r}; available: {', '.join(SCENARIOS)}") from None


_ADDED: dict[str, Scenario] = {}


def add(key: str, scenario: Scenario) -> None:
    """Make :func:`get` (and so :func:`run`, the exports and the campaign) find ``scenario`` under ``key`` in
    this process: :func:`fmus.system.scenario_from_file` adds a system file's under its resolved path."""
    _ADDED[key] = scenario


def is_added(key: str) -> bool:
    """A scenario was :func:`add` ed under ``key`` in this process."""
    return key in _ADDED


def _items(scenario: Scenario):
    """The scenario's definitions; one without a ``default_experiment`` gets the scenario's own run.

    FMUs that several scenarios share (``ltv_common``) declare theirs in their definitions: one
    definition per FMU, whichever scenario builds it.
    """
    for item in scenario.definitions():
        definition, extra_modules = item if isinstance(item, tuple) else (item, ())
        if definition.default_experiment is None:
            definition = replace(definition, default_experiment=experiment(scenario.stop_time, scenario.step))
        yield definition, tuple(extra_modules)


def _damage(path: Path, platforms=None) -> str | None:
    """Why a cached FMU cannot be used as it is (None: it can); its binary is looked for where its FMI version
    (its modelDescription) has it, for each of ``platforms`` (default: this machine's)."""
    try:
        description = read_model_description(str(path))
    except Exception as exc:  # lxml, zip and schema errors alike: the file is damaged
        return f"its modelDescription.xml cannot be read ({type(exc).__name__}: {exc})"
    if description.coSimulation is None:
        return "it has no co-simulation interface"
    identifier = description.coSimulation.modelIdentifier
    with zipfile.ZipFile(path) as archive:
        names = set(archive.namelist())
    for platform in platforms_of(platforms):
        target = native.target(platform)
        if target is native.host():
            folder = fmpy.platform if description.fmiVersion.startswith("2") else fmpy.platform_tuple
        else:
            folder = target.name if description.fmiVersion.startswith("2") else target.fmi3_folder
        binary = f"binaries/{folder}/{identifier}{target.suffix}"
        if binary not in names:
            return f"it has no binary {binary}"
    return None


def ensure_definitions(items, build_dir: Path, force: bool, fmi_version: int, standalone: bool = False,
                       platforms=None) -> dict[str, Path]:
    """``(definition, extra_modules)`` pairs built into ``build_dir`` (its FMI 3.0 folder for 3) unless the FMU
    there is current (:func:`fmus.builder.why_not_current`: judged by content; an FMU edited since its build
    is rebuilt with a note) or ``force``; model name -> path."""
    paths = {}
    folder = build_folder(build_dir, fmi_version)
    for definition, extra_modules in items:
        path = folder / f"{definition.model_name}.fmu"
        stale = "rebuild asked" if force else why_not_current(path, definition, extra_modules, fmi_version,
                                                              standalone=standalone, platforms=platforms)
        if stale is not None:
            if stale.startswith(("edited", "no build record")):      # not the file obsfmu built there
                print(f"obsfmu: note: {path}: {stale}; rebuilding it", file=sys.stderr)
            build_fmu(definition, folder, extra_modules, fmi_version, standalone=standalone, platforms=platforms)
        elif (problem := _damage(path, platforms)) is not None:
            print(f"obsfmu: note: {path}: {problem}; rebuilding it", file=sys.stderr)
            build_fmu(definition, folder, extra_modules, fmi_version, standalone=standalone, platforms=platforms)
        problem = _damage(path, platforms)
        if problem is not None:
            raise SimulationError(f"{path}: {problem} even after rebuilding it")
        paths[definition.model_name] = path
    return paths


def ensure_fmus(scenario: Scenario, build_dir: Path, force: bool = False, fmi_version: int = 2,
                standalone: bool = False, platforms=None) -> dict[str, Path]:
    """Build the scenario's FMUs into ``build_dir`` unless current, intact ones are there.

    A cached FMU built from the same sources but damaged since (unreadable modelDescription,
    missing binary) is rebuilt with a note on stderr.  FMI 3.0 FMUs (``fmi_version=3``) go to
    ``build_dir/fmi3`` (:func:`fmus.fmi3.build_folder`).  ``standalone``: FMUs that carry their Python
    (:mod:`fmus.standalone`); an FMU of the other build is rebuilt.  ``platforms``: what the FMUs have binaries
    for (default this machine's; ``"linux64,win64"``, :func:`fmus.builder.build_fmu`).
    """
    return ensure_definitions(_items(scenario), build_dir, force, fmi_version, standalone, platforms)


def ensure_all(scenarios, build_dir: Path, force: bool = False, fmi_version: int = 2,
               standalone: bool = False, platforms=None, kernels: str = "c") -> dict[str, Path]:
    """Every distinct FMU of ``scenarios``, each built once (``ltv-ls`` and ``ltv-ls-bounded`` share theirs);
    ``kernels`` ``"python"``: FMUs that always step in Python (:attr:`FmuDefinition.kernels`).

    Two scenarios naming the same model must define it identically (else :class:`SimulationError`).
    """
    distinct: dict[str, tuple] = {}
    for scenario in scenarios:
        for definition, extra_modules in _items(scenario):
            definition = replace(definition, kernels=kernels)
            known = distinct.setdefault(definition.model_name, (definition, extra_modules, scenario.name))
            if (known[0].to_json(), known[1]) != (definition.to_json(), extra_modules):
                raise SimulationError(f"{definition.model_name}: scenarios {known[2]!r} and {scenario.name!r} "
                                      f"define this FMU differently")
    return ensure_definitions(((d, extra) for d, extra, _ in distinct.values()), build_dir, force, fmi_version, standalone,
                   platforms)


_OVERRIDE = re.compile(r"^(?P<instance>[A-Za-z_]\w*)\.(?P<variable>[^=]+)=(?P<value>.+)$")


def parse_overrides(items: list[str]) -> list[tuple[str, str, float]]:
    """``["plant.x0[1]=0.1", "observer.poles=[-10,-12]", ...]`` -> ``[("plant", "x0[1]", 0.1),
    ("observer", "poles[1]", -10.0), ("observer", "poles[2]", -12.0), ...]`` (finite numbers only; a list
    sets a whole array parameter, element by element)."""
    parsed = []
    for item in items:
        match = _OVERRIDE.match(item.strip())
        if not match:
            raise SimulationError(f"--set {item!r}: expected INSTANCE.VARIABLE=VALUE")
        text, variable = match["value"].strip(), match["variable"].strip()
        if text.startswith("[") and text.endswith("]"):
            entries = [e.strip() for e in text[1:-1].split(",")]
            parsed += [(match["instance"], f"{variable}[{i}]", _override_value(item, e))
                       for i, e in enumerate(entries, start=1)]
        else:
            parsed.append((match["instance"], variable, _override_value(item, text)))
    return parsed


def _override_value(item: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise SimulationError(f"--set {item!r}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise SimulationError(f"--set {item!r}: the value must be a finite number")
    return value


def _variables(fmu: Path) -> dict:
    """The FMU's variables by FMI 2.0 name (an FMI 3.0 FMU's array elements: fmus/fmi3/elements.py)."""
    return {v.name: v for v in scalar_variables(fmu)}


def _start(variable) -> float | None:
    if variable.start is None:
        return None
    if variable.type == "Boolean":
        return float(str(variable.start).lower() in ("1", "true"))
    return float(variable.start)


def _check_override(instance: str, name: str, value: float, variables: dict, connected: set[str]) -> None:
    """``value`` may be set as the start value of ``instance.name`` (causality, type, declared range)."""
    where = f"--set {instance}.{name}"
    if name not in variables:
        close = difflib.get_close_matches(name, list(variables), n=3)
        hint = f"; did you mean {', '.join(close)}?" if close else ""
        raise SimulationError(f"{where}: no such variable{hint}")
    variable = variables[name]
    if variable.causality == "output":
        raise SimulationError(f"{where}: is an output of {instance} and cannot be set")
    if variable.causality not in ("parameter", "input") or variable.variability == "constant":
        raise SimulationError(f"{where}: is a {variable.variability} {variable.causality} variable and "
                              "cannot be set")
    if name in connected:
        raise SimulationError(f"{where}: is a connected input; its value comes from the connection")
    if variable.type in ("Integer", "Enumeration") and value != int(value):
        raise SimulationError(f"{where}={value:g}: {variable.type} variable, expected a whole number")
    if variable.type == "Boolean" and value not in (0.0, 1.0):
        raise SimulationError(f"{where}={value:g}: Boolean variable, expected 0 or 1")
    for bound, outside, word in ((variable.min, value.__lt__, "below the minimum"),
                                 (variable.max, value.__gt__, "above the maximum")):
        if bound is not None and outside(float(bound)):
            meaning = f" ({variable.description})" if variable.description else ""
            raise SimulationError(f"{where}={value:g}: {word} {float(bound):g} declared by the FMU{meaning}")


def _connected_inputs(scenario: Scenario, instance: str, variables: dict) -> set[str]:
    ports = [c.target.partition(".")[2] for c in scenario.connections if c.target.partition(".")[0] == instance]
    return {name for name in variables for port in ports if name == port or name.startswith(port + "[")}


def system(scenario: Scenario, fmus: dict[str, Path], overrides=()) -> System:
    """The scenario's system with ``overrides`` applied to the start values (checked against the FMUs)."""
    components = [Component(instance, fmus[model], dict(start)) for instance, model, start in scenario.components]
    by_name = {c.name: c for c in components}
    described = {}
    for instance, variable, value in overrides:
        if instance not in by_name:
            raise SimulationError(f"--set {instance}.{variable}: unknown instance {instance!r}; "
                                  f"instances: {', '.join(by_name)}")
        if instance not in described:
            variables = _variables(by_name[instance].fmu)
            described[instance] = variables, _connected_inputs(scenario, instance, variables)
        _check_override(instance, variable, value, *described[instance])
        by_name[instance].start[variable] = value
    return System(components, list(scenario.connections))


def changed_parameters(result: Result) -> str:
    """``""`` when ``result`` ran with its scenario's own parameters, else which ones it changed.

    Summaries use it to decide whether a stored reference or a paper's table is this run's.
    """
    if result.info is None:
        return "the run's parameters are unknown"
    changed = result.info.changed
    return "" if not changed else "parameters changed: " + ", ".join(f"{k} = {v:g}" for k, v in changed.items())


def run_info(scenario: Scenario, fmus: dict[str, Path], overrides=(), **settings) -> RunInfo:
    """Units, parameter values and defaults of a run of ``scenario`` (see :class:`RunInfo`)."""
    info = RunInfo(scenario=scenario.name, time_unit=scenario.time_unit, **settings)
    given = {}
    for instance, model, start in scenario.components:
        for variable in scalar_variables(fmus[model]):
            key = f"{instance}.{variable.name}"
            if variable.causality == "output" and variable.unit:
                info.units[key] = variable.unit
            elif variable.causality in ("parameter", "input") and (value := _start(variable)) is not None:
                info.defaults[key] = float(start.get(variable.name, value))
        given.update({f"{instance}.{name}": float(value) for name, value in start.items()})
    info.defaults.update(given)
    info.parameters = {**info.defaults, **{f"{i}.{v}": float(value) for i, v, value in overrides}}
    return info


def run(name: str, build_dir: Path | str = "build", *, stop_time: float | None = None,
        step: float | None = None, order: str | None = None, coupling: str | None = None,
        overrides=(), progress: bool = False, tolerance: float | None = None, recorder: Recorder | None = None,
        should_stop: Callable[[], bool] | None = None, fmi_version: int = 2,
        ramp: int | None = None) -> tuple[Result, Summary | None]:
    """Build (if needed) and co-simulate scenario ``name``; returns the result and its summary.

    ``recorder`` receives the communication points (default: in memory) and ``should_stop`` is
    asked after each of them (see :meth:`fmus.master.Session.run`).  The result carries a
    :class:`RunInfo`; an interrupted run has no summary.  FMU warnings of a successful run are
    printed once each on stderr (errors are part of the :class:`SimulationError`).  ``fmi_version``
    3 runs the scenario's FMI 3.0 FMUs (same results, same column names).  ``None`` for a setting
    means the scenario's default (``ramp``: its start-up ramp, :func:`fmus.master.cosimulate`).
    """
    scenario = get(name)
    tolerance = scenario.tolerance if tolerance is None else tolerance
    if (order or scenario.order) == "adaptive" and scenario.not_adaptive:
        raise SimulationError(f"{name}: the adaptive master cannot run this scenario: {scenario.not_adaptive}")
    floor = scenario.adaptive_floor
    if (order or scenario.order) == "adaptive" and floor and tolerance < floor[0]:
        raise SimulationError(f"{name}: the adaptive master cannot run this scenario at tol {tolerance:g} (use a "
                              f"tolerance of at least {floor[0]:g}, or a fixed step): {floor[1]}")
    settings = dict(stop_time=scenario.stop_time if stop_time is None else stop_time,
                    step=scenario.step if step is None else step,
                    order=order or scenario.order, coupling=coupling or scenario.coupling)
    check_step(scenario, **settings)
    fmus = ensure_fmus(scenario, Path(build_dir), fmi_version=fmi_version)
    the_system = system(scenario, fmus, overrides)
    info = run_info(scenario, fmus, overrides, **settings)
    with Session(the_system, echo_log=False) as session:
        result = session.run(**settings, progress=progress, tolerance=tolerance, recorder=recorder,
                             should_stop=should_stop, time_unit=scenario.time_unit,
                             ramp=scenario.ramp if ramp is None else ramp)
        _print_warnings(session)
    result.info = info
    summary = scenario.summarize(result) if scenario.summarize and not result.interrupted else None
    return result, summary


#: a step this many times the scenario's default gets a warning (README: "Choosing the communication step")
STEP_WARNING_RATIO = 10.0


def check_step(scenario: Scenario, stop_time: float, step: float, order: str, coupling: str) -> None:
    """A step longer than the run is an error naming ``--step``; a fixed step far beyond the scenario's
    default gets one line on stderr with the expected growth of the coupling error.

    The coupling error of a fixed-step run grows like ``h^2`` with linear coupling and like ``h`` with
    held inputs (README, "Choosing the communication step"), so a step ``r`` times the default costs
    about ``r^2`` (``r``) times the error the scenario's default was chosen for."""
    unit = scenario.time_unit
    if step > stop_time:
        raise SimulationError(f"--step {step:g} {unit}: longer than the run (--stop-time {stop_time:g} {unit}); "
                              f"{scenario.name}'s default step is {scenario.step:g} {unit}")
    ratio = step / scenario.step
    if order != "adaptive" and ratio > STEP_WARNING_RATIO:
        power = 2 if coupling == "linear" else 1
        print(f"obsfmu: warning: --step {step:g} {unit} is {ratio:.3g} times {scenario.name}'s default "
              f"{scenario.step:g} {unit}: with {coupling} coupling the coupling error grows like h^{power}, to about "
              f"{ratio ** power:.2g} times the error at the default (README: Choosing the communication step)",
              file=sys.stderr)
    if order != "adaptive" and scenario.fastest is not None:
        _check_rate(scenario, step, coupling)


#: the relative coupling error above which a step is worth a warning
COUPLING_ERROR_WARNING = 1e-2


def _check_rate(scenario: Scenario, step: float, coupling: str) -> None:
    """One line on stderr when ``step`` is long against the fastest rate ``|lambda|`` of the system: measured
    on ship (README; an unstable plant, so a pessimistic case), the coupling error is about
    ``(h |lambda|)^2 / 3`` with linear coupling and ``h |lambda| / 3`` with held inputs, relative to the
    signals; a stable system often loses much less (the pendulum example: 6e-4 at h |lambda| = 0.6)."""
    rate, what = scenario.fastest
    product, unit = step * rate, scenario.time_unit
    expected = product ** 2 / 3 if coupling == "linear" else product / 3
    if expected > COUPLING_ERROR_WARNING:
        advised = (3 * COUPLING_ERROR_WARNING) ** (0.5 if coupling == "linear" else 1) / rate
        print(f"obsfmu: warning: step {step:g} {unit}: h |lambda| = {product:.3g} for the fastest dynamics "
              f"({what}, |lambda| = {rate:.3g} 1/{unit}); with {coupling} coupling expect a coupling error of up to about "
              f"{expected:.2g} relative to the signals (the ship's, unstable, lost that much); a step of at most {advised:.2g} {unit} keeps it below "
              f"{COUPLING_ERROR_WARNING:g} (README: Choosing the communication step); an adaptive observer's converged "
              f"flag stays 0 while (h |lambda|)^2/3 exceeds its converged_tolerance", file=sys.stderr)


def _print_warnings(session: Session) -> None:
    seen = set()
    for instance, status, message in getattr(getattr(session, "logger", None), "messages", []):
        if (status == "WARNING" or instance == "master") and (instance, message) not in seen:
            seen.add((instance, message))          # the master's notes: e.g. the algebraic loops it solved
            print(f"[{'note' if instance == 'master' else status}] {instance}: {message}", file=sys.stderr)


#: every scenario, by name (discovered last: the scenario modules import the helpers above)
SCENARIOS: dict[str, Scenario] = _registry()
