"""Scenarios: the papers' examples as co-simulations of FMUs.

A :class:`Scenario` lists the FMUs it needs (as definitions, built on
demand into the build directory), the instances and connections, and the
defaults a user should not have to know: stop time, communication step,
order and coupling -- each chosen against the scenario's monolithic
reference and documented in its module.  :func:`run` builds what is
missing, applies ``--set`` overrides and co-simulates.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from ..builder import build_fmu, is_current
from ..definition import FmuDefinition
from ..master import Component, Connection, SimulationError, System, cosimulate
from ..result import Result

__all__ = ["Scenario", "Summary", "SCENARIOS", "get", "ensure_fmus", "ensure_all", "run", "parse_overrides"]


@dataclass
class Summary:
    """What ``obsfmu run`` prints: a few lines of text and the numbers behind them."""

    lines: list[str]
    metrics: dict[str, float] = field(default_factory=dict)

    def __str__(self) -> str:
        return "\n".join(self.lines)


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
    plot: Callable[[Result, Path], None] | None = None
    time_unit: str = "s"  #: the unit of time of the models (``h`` for the chemostat)
    #: spacing of the rows that ``obsfmu all`` writes to CSV (None: every communication point)
    output_interval: float | None = None
    #: why the adaptive master cannot run this scenario (it is then refused at once), or None
    not_adaptive: str | None = None
    #: the first step split into h/2^ramp, ..., h/2 (see :func:`fmus.master.cosimulate`)
    ramp: int = 0


def _registry() -> dict[str, Scenario]:
    """Every sub-package of this package that defines ``SCENARIO`` (or ``SCENARIOS``)."""
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


SCENARIOS: dict[str, Scenario] = _registry()


def get(name: str) -> Scenario:
    try:
        return SCENARIOS[name]
    except KeyError:
        raise SimulationError(f"unknown scenario {name!r}; available: {', '.join(SCENARIOS)}") from None


def _items(scenario: Scenario):
    for item in scenario.definitions():
        definition, extra_modules = item if isinstance(item, tuple) else (item, ())
        yield definition, tuple(extra_modules)


def _ensure(items, build_dir: Path, force: bool) -> dict[str, Path]:
    paths = {}
    for definition, extra_modules in items:
        path = Path(build_dir) / f"{definition.model_name}.fmu"
        if force or not is_current(path, definition, extra_modules):
            build_fmu(definition, build_dir, extra_modules)
        paths[definition.model_name] = path
    return paths


def ensure_fmus(scenario: Scenario, build_dir: Path, force: bool = False) -> dict[str, Path]:
    """Build the scenario's FMUs into ``build_dir`` unless current ones are there."""
    return _ensure(_items(scenario), build_dir, force)


def ensure_all(scenarios, build_dir: Path, force: bool = False) -> dict[str, Path]:
    """Every distinct FMU of ``scenarios``, each built once (``ltv-ls`` and ``ltv-ls-bounded`` share theirs).

    Two scenarios naming the same model must define it identically (else :class:`SimulationError`).
    """
    distinct: dict[str, tuple] = {}
    for scenario in scenarios:
        for definition, extra_modules in _items(scenario):
            known = distinct.setdefault(definition.model_name, (definition, extra_modules, scenario.name))
            if (known[0].to_json(), known[1]) != (definition.to_json(), extra_modules):
                raise SimulationError(f"{definition.model_name}: scenarios {known[2]!r} and {scenario.name!r} "
                                      f"define this FMU differently")
    return _ensure(((d, extra) for d, extra, _ in distinct.values()), build_dir, force)


_OVERRIDE = re.compile(r"^(?P<instance>[A-Za-z_]\w*)\.(?P<variable>[^=]+)=(?P<value>.+)$")


def parse_overrides(items: list[str]) -> list[tuple[str, str, float]]:
    """``["plant.x0[1]=0.1", ...]`` -> ``[("plant", "x0[1]", 0.1), ...]`` (values are numbers)."""
    parsed = []
    for item in items:
        match = _OVERRIDE.match(item.strip())
        if not match:
            raise SimulationError(f"--set {item!r}: expected INSTANCE.VARIABLE=VALUE")
        try:
            value = float(match["value"])
        except ValueError:
            raise SimulationError(f"--set {item!r}: {match['value']!r} is not a number") from None
        parsed.append((match["instance"], match["variable"].strip(), value))
    return parsed


def system(scenario: Scenario, fmus: dict[str, Path], overrides=()) -> System:
    """The scenario's system with ``overrides`` applied to the start values."""
    components = [Component(instance, fmus[model], dict(start)) for instance, model, start in scenario.components]
    by_name = {c.name: c for c in components}
    for instance, variable, value in overrides:
        if instance not in by_name:
            raise SimulationError(f"--set {instance}.{variable}: unknown instance {instance!r}; "
                                  f"instances: {', '.join(by_name)}")
        by_name[instance].start[variable] = value
    return System(components, list(scenario.connections))


def run(name: str, build_dir: Path | str = "build", *, stop_time: float | None = None,
        step: float | None = None, order: str | None = None, coupling: str | None = None,
        overrides=(), progress: bool = False, tolerance: float = 1e-6,
        ramp: int | None = None) -> tuple[Result, Summary | None]:
    """Build (if needed) and co-simulate scenario ``name``; returns the result and its summary.

    ``None`` for a setting means the scenario's default (``ramp``: its start-up ramp).
    """
    scenario = get(name)
    if (order or scenario.order) == "adaptive" and scenario.not_adaptive:
        raise SimulationError(f"{name}: the adaptive master cannot run this scenario: {scenario.not_adaptive}")
    fmus = ensure_fmus(scenario, Path(build_dir))
    result = cosimulate(system(scenario, fmus, overrides),
                        stop_time=scenario.stop_time if stop_time is None else stop_time,
                        step=scenario.step if step is None else step,
                        order=order or scenario.order,
                        coupling=coupling or scenario.coupling,
                        progress=progress,
                        tolerance=tolerance,
                        ramp=scenario.ramp if ramp is None else ramp)
    return result, scenario.summarize(result) if scenario.summarize else None
