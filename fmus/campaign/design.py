"""A campaign: one scenario run over many values of some of its FMUs' parameters.

:class:`Campaign` is the study as the user states it (scenario, ``vary``
specs, samples, seed, run settings, fixed ``--set`` values); :meth:`Campaign.plan`
builds the FMUs, checks every name and value against their modelDescription
and returns a :class:`Plan`: the resolved run settings and the list of
:class:`Sample` s.  Grid and list specs are combined as a product; random
specs give ``samples`` draws each, and every grid point is combined with
the same draws (common random numbers).  A sample's id is a hash of
everything that determines its result (scenario, run settings, fixed and
varied values): a rerun recognises the samples already done.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import zipfile
from dataclasses import dataclass, field
from pathlib import Path


from .. import scenarios
from ..system import resolve
from ..master import COUPLINGS, ORDERS
from ..master.session import check_run_settings
from ..toml_numbers import LARGEST, huge_integer
from .errors import CampaignError
from .measures import Measure, measure_for
from .spec import Choice, Distribution, Grid, Spec, rng_for, spec_from_value

__all__ = ["Campaign", "Plan", "Sample", "Variable", "fmu_fingerprint", "MAX_SAMPLES"]

MAX_SAMPLES = 1_000_000
DEFAULT_TIME_LIMIT = 600.0   #: seconds of wall time per sample (checked between communication steps)
_SETTABLE = ("parameter", "input")


@dataclass(frozen=True)
class Variable:
    """A settable FMU variable, as its modelDescription declares it."""

    name: str           #: "instance.variable"
    type: str           #: Real, Integer, Enumeration, Boolean
    unit: str | None
    description: str | None


@dataclass(frozen=True)
class Sample:
    id: str
    values: dict[str, float]   #: "instance.variable" -> value, in the order of the campaign's vary


@dataclass
class Plan:
    """A campaign ready to run: resolved settings, FMUs and samples."""

    campaign: "Campaign"
    scenario: scenarios.Scenario
    settings: dict            #: stop_time, step, order, coupling (+ tolerance for the adaptive master)
    fmus: dict[str, Path]     #: model name -> .fmu
    fmu_set: str              #: fingerprint of the FMUs' contents
    variables: dict[str, Variable]
    measure: Measure
    samples: list[Sample]

    @property
    def time_unit(self) -> str:
        return self.measure.time_unit or self.scenario.time_unit


def _split(name: str, option: str) -> tuple[str, str]:
    instance, dot, variable = name.partition(".")
    if not dot or not instance or not variable:
        raise CampaignError(f"{option} {name!r}: expected INSTANCE.VARIABLE, e.g. plant.k[1]")
    return instance, variable.strip()


@dataclass
class Campaign:
    """A sweep or Monte-Carlo study of one scenario.

    Parameters
    ----------
    scenario : str
        Scenario name (``obsfmu list``).
    vary : dict
        ``"instance.variable"`` -> SPEC string (``"-3:3:7"``, ``"[1, 2]"``,
        ``"uniform(0, 1)"``, ...), a list of numbers, or a parsed spec.
    samples : int, optional
        Number of random draws (required with random specs, refused without).
    seed : int
        Seed of the draws (each variable has its own stream).
    stop_time, step, master, coupling, tolerance
        As for ``obsfmu run`` (``None``: the scenario's default).
    set : dict
        Fixed ``"instance.variable"`` -> value for every sample (``--set``).
    time_limit : float
        Wall-time limit per sample in seconds; a sample over it is a row with status ``timeout``.
    time_metric, error_metric : str or list of str, optional
        Summary metrics that define the convergence time and the final error
        (default: the scenario's, see :mod:`fmus.campaign.measures`).
    build_dir : path
        Where the FMUs are (built when missing or stale).
    """

    scenario: str
    vary: dict = field(default_factory=dict)
    samples: int | None = None
    seed: int = 0
    stop_time: float | None = None
    step: float | None = None
    master: str | None = None
    coupling: str | None = None
    tolerance: float | None = None
    set: dict = field(default_factory=dict)
    time_limit: float = DEFAULT_TIME_LIMIT
    time_metric: str | list | None = None
    error_metric: str | list | None = None
    build_dir: Path | str = "build"

    def __post_init__(self) -> None:
        self.specs: dict[str, Spec] = {}
        for name, value in self.vary.items():
            _split(name, "--vary")
            parsed = isinstance(value, (Grid, Choice, Distribution))
            self.specs[name] = value if parsed else spec_from_value(name, value)
        if not self.specs:
            raise CampaignError("vary: a campaign varies at least one INSTANCE.VARIABLE (--vary NAME=SPEC)")
        self.fixed = {name: _number(f"--set {name}", value) for name, value in self.set.items()}
        for name in self.fixed:
            _split(name, "--set")
        both = sorted(set(self.fixed) & set(self.specs))
        if both:
            raise CampaignError(f"{', '.join(both)}: both varied (--vary) and fixed (--set); choose one")
        randoms = [n for n, s in self.specs.items() if isinstance(s, Distribution)]
        if randoms and self.samples is None:
            raise CampaignError(f"--samples: random specs ({', '.join(randoms)}) need the number of samples")
        if not randoms and self.samples is not None:
            raise CampaignError("--samples: only random specs (uniform/normal/loguniform) take a number of samples; "
                                "grids and lists define their own points")
        if self.samples is not None and (isinstance(self.samples, bool) or int(self.samples) != self.samples
                                         or self.samples < 1):
            raise CampaignError(f"--samples: must be a whole number >= 1, got {self.samples!r}")
        if isinstance(self.seed, bool) or int(self.seed) != self.seed or self.seed < 0:
            raise CampaignError(f"--seed: must be a whole number >= 0, got {self.seed!r}")
        if not (isinstance(self.time_limit, (int, float)) and self.time_limit > 0
                and abs(self.time_limit) <= LARGEST and math.isfinite(self.time_limit)):
            raise CampaignError(f"--time-limit: must be a positive number of seconds, got {self.time_limit!r}")
        for option, value in (("--stop-time", self.stop_time), ("--step", self.step)):
            if value is not None and not (math.isfinite(_float(option, value)) and value > 0):
                raise CampaignError(f"{option}: must be a positive number, got {value!r}")
        if self.master is not None and self.master not in ORDERS:
            raise CampaignError(f"--master: {self.master!r} is not one of {', '.join(ORDERS)}")
        if self.coupling is not None and self.coupling not in COUPLINGS:
            raise CampaignError(f"--coupling: {self.coupling!r} is not one of {', '.join(COUPLINGS)}")

    # -- construction from a TOML file
    @classmethod
    def from_toml(cls, path: Path | str, **overrides) -> "Campaign":
        """Read a campaign file (see ``docs/campaigns.md``); ``overrides`` (not None) replace its values."""
        try:
            import tomllib
        except ModuleNotFoundError:  # Python 3.10
            import tomli as tomllib
        try:
            with open(path, "rb") as handle:
                data = tomllib.load(handle)
        except FileNotFoundError:
            raise CampaignError(f"--config: {path} does not exist") from None
        except tomllib.TOMLDecodeError as exc:
            raise CampaignError(f"--config {path}: not valid TOML ({exc})") from None
        huge = huge_integer(data)
        if huge:
            raise CampaignError(f"--config {path}: {huge}")
        known = {f for f in cls.__dataclass_fields__}
        unknown = sorted(set(data) - known)
        if unknown:
            raise CampaignError(f"--config {path}: unknown key(s) {', '.join(unknown)}; "
                                f"known: {', '.join(sorted(known))}")
        for key in ("vary", "set"):
            if key in data and not isinstance(data[key], dict):
                raise CampaignError(f"--config {path}: [{key}] must be a table of \"instance.variable\" = ...")
        merged = {**data, **{k: v for k, v in overrides.items() if v is not None and k not in ("vary", "set")}}
        for key in ("vary", "set"):   # command-line entries add to (or replace) the file's
            merged[key] = {**data.get(key, {}), **(overrides.get(key) or {})}
        if "scenario" not in merged:
            raise CampaignError(f"--config {path}: no scenario (scenario = \"name\" or the SCENARIO argument)")
        return cls(**merged)

    # -- resolution against the scenario and its FMUs
    def plan(self) -> Plan:
        """Build/check the FMUs, check every name and value, and list the samples."""
        scenario = resolve(self.scenario)
        settings = {
            "stop_time": float(scenario.stop_time if self.stop_time is None else self.stop_time),
            "step": float(scenario.step if self.step is None else self.step),
            "order": self.master or scenario.order,
            "coupling": self.coupling or scenario.coupling,
        }
        if settings["order"] == "adaptive":      # the scenario's (a system file's [experiment] tolerance)
            settings["tolerance"] = float(scenario.tolerance if self.tolerance is None else self.tolerance)
        elif scenario.ramp:
            settings["ramp"] = scenario.ramp     # its start-up ramp, as 'obsfmu run' (fmus.master.cosimulate)
        check_run_settings(settings["stop_time"], settings["step"], settings["order"], 0.0, settings["coupling"],
                           settings.get("tolerance", 1e-6))      # every sample's: refused once, before any build
        fmus = scenarios.ensure_fmus(scenario, Path(self.build_dir))
        descriptions = _model_variables(scenario, fmus)
        for name in list(self.specs) + list(self.fixed):
            _check_name(name, descriptions, scenario)
        variables = {name: describe(name, descriptions) for name in list(self.specs) + list(self.fixed)}
        for name, spec in self.specs.items():
            _check_values(name, spec, variables[name])
        for name, value in self.fixed.items():
            _check_value(f"--set {name}", variables[name], value)
        samples = self._samples(scenario.name, settings)
        return Plan(self, scenario, settings, fmus, fmu_fingerprint(fmus.values()),
                    {name: variables[name] for name in self.specs},
                    measure_for(scenario, self.time_metric, self.error_metric), samples)

    def _samples(self, scenario: str, settings: dict) -> list[Sample]:
        sizes = [s.count if isinstance(s, Grid) else len(s.items) for s in self.specs.values()
                 if not isinstance(s, Distribution)]
        count = math.prod(sizes) * (self.samples or 1)          # before any grid is made
        if count > MAX_SAMPLES:
            raise CampaignError(f"vary: {count} samples is more than {MAX_SAMPLES}; use fewer points")
        axes = {n: s.values() for n, s in self.specs.items() if not isinstance(s, Distribution)}
        draws = {n: s.draw(rng_for(self.seed, n), self.samples) for n, s in self.specs.items()
                 if isinstance(s, Distribution)}
        base = {"scenario": scenario, "settings": settings, "fixed": {k: self.fixed[k] for k in sorted(self.fixed)}}
        samples = []
        for point in itertools.product(*axes.values()):
            for j in range(self.samples or 1):
                chosen = dict(zip(axes, (float(v) for v in point)))
                chosen.update({n: float(d[j]) for n, d in draws.items()})
                values = {n: chosen[n] for n in self.specs}
                samples.append(Sample(sample_id(base, values), values))
        return samples


def sample_id(base: dict, values: dict[str, float]) -> str:
    """16 hex digits of the SHA-256 of the sample's inputs (exact float reprs, sorted keys)."""
    text = json.dumps({**base, "values": {k: values[k] for k in sorted(values)}}, sort_keys=True,
                      separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def fmu_fingerprint(paths) -> str:
    """12 hex digits identifying the FMUs' contents (names, CRCs and sizes of their members: zip timestamps
    do not matter, a rebuilt FMU with other code or binaries does)."""
    digest = hashlib.sha256()
    for path in sorted(Path(p) for p in paths):
        digest.update(path.name.encode())
        with zipfile.ZipFile(path) as archive:
            for info in sorted(archive.infolist(), key=lambda i: i.filename):
                digest.update(f"{info.filename}:{info.CRC}:{info.file_size};".encode())
    return digest.hexdigest()[:12]


def _float(option: str, value) -> float:
    """``float(value)``; a :class:`CampaignError` naming ``option`` for an integer beyond a float."""
    try:
        return float(value)
    except OverflowError:
        raise CampaignError(f"{option}: {str(value)[:20]}... is beyond the range of a float") from None


def _number(option: str, value) -> float:
    try:
        number = _float(option, value)
    except (TypeError, ValueError):
        raise CampaignError(f"{option}: {value!r} is not a number") from None
    if not math.isfinite(number):
        raise CampaignError(f"{option}: must be finite, got {value!r}")
    return number


def _model_variables(scenario: scenarios.Scenario, fmus: dict[str, Path]) -> dict[str, dict]:
    """instance -> {variable name -> fmpy ScalarVariable} for every instance of the scenario."""
    from fmpy import read_model_description

    descriptions = {}
    for instance, model, _ in scenario.components:
        descriptions[instance] = {v.name: v for v in read_model_description(str(fmus[model])).modelVariables}
    return descriptions


def _connected(scenario: scenarios.Scenario, instance: str, variable: str) -> str | None:
    for connection in scenario.connections:
        target_instance, _, target = connection.target.partition(".")
        if target_instance == instance and (variable == target or variable.startswith(target + "[")):
            return connection.source
    return None


def _check_name(name: str, descriptions: dict[str, dict], scenario: scenarios.Scenario) -> None:
    import difflib

    instance, variable = _split(name, "--vary/--set")
    if instance not in descriptions:
        raise CampaignError(f"{name}: unknown instance {instance!r}; {scenario.name} has {', '.join(descriptions)}")
    found = descriptions[instance].get(variable)
    if found is None:
        settable = [n for n, v in descriptions[instance].items() if v.causality in _SETTABLE]
        close = difflib.get_close_matches(variable, settable, n=3)
        hint = f"; did you mean {', '.join(close)}?" if close else f"; settable: {', '.join(settable[:12])}, ..."
        raise CampaignError(f"{name}: {instance} has no variable {variable!r}{hint}")
    if found.causality not in _SETTABLE or found.variability == "constant":
        raise CampaignError(f"{name}: is {'a constant' if found.variability == 'constant' else 'an ' + found.causality}"
                            f"; a campaign sets parameters and unconnected inputs")
    source = _connected(scenario, instance, variable)
    if source:
        raise CampaignError(f"{name}: is an input connected to {source}, which overwrites it every step")
    if found.type not in ("Real", "Integer", "Enumeration", "Boolean"):
        raise CampaignError(f"{name}: has type {found.type}, which a campaign cannot set")


def _check_value(option: str, variable, value: float) -> None:
    if variable.type in ("Integer", "Enumeration") and value != int(value):
        raise CampaignError(f"{option}: {variable.name} is an {variable.type}; {value!r} is not a whole number")
    if variable.type == "Boolean" and value not in (0.0, 1.0):
        raise CampaignError(f"{option}: {variable.name} is a Boolean; use 0 or 1, not {value!r}")


def _check_values(name: str, spec: Spec, variable) -> None:
    if isinstance(spec, Distribution):
        if variable.type != "Real":
            raise CampaignError(f"{name}={spec}: {variable.type} variable; random draws are real numbers "
                                f"(use a list or a grid of whole numbers)")
        return
    for value in spec.values():
        _check_value(f"{name}={spec}", variable, float(value))


def describe(variable_name: str, descriptions: dict[str, dict]) -> Variable:
    instance, variable = _split(variable_name, "--vary")
    found = descriptions[instance][variable]
    return Variable(variable_name, found.type, found.unit, found.description)
