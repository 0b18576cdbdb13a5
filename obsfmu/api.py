"""obsfmu from Python: build or load a system, run it, get arrays; build and export its FMUs.

>>> import obsfmu
>>> system = obsfmu.System("motor", stop_time=1.0, step=1e-3)
>>> system.add("plant", obsfmu.lti(A=[[0, 1], ["-16000/250", -2]], B=[[0], [1]], C=[[1, 0]]))
>>> system.values["plant.u"] = 1.0
>>> result = obsfmu.run(system)
>>> result.time, result["plant.y"], result.units

``run`` accepts a :class:`System`, a system file's path or a paper scenario's name (:func:`scenarios`).
FMUs are built once into the cache (``$OBSFMU_CACHE/build``, default ``~/.cache/obsfmu/build``) unless a
``build_dir`` is given.  See docs/python.md.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import _internals as _in
from ._toml import dumps

__all__ = ["System", "Result", "lti", "from_statespace", "load", "run", "build", "export", "scenario",
           "scenarios", "ParameterError", "SimulationError", "cache_dir"]

ParameterError = _in.ParameterError
SimulationError = _in.SimulationError


def cache_dir() -> Path:
    """Where the API keeps its system files and builds: ``$OBSFMU_CACHE`` (default ``~/.cache/obsfmu``)."""
    return _in.obsfmu_cache()


# ----------------------------------------------------------------------------------------------- systems

def lti(A, B=None, C=None, D=None, *, x0=None, sample_time=None, state_units=None, input_units=None,
        output_units=None, state_names=None, input_names=None, output_names=None, description: str = "") -> dict:
    """An ``lti`` component (docs/system-file-reference.md): matrices of numbers or constant expressions
    (``"-16000/250"``, read by the project's expression grammar, never ``eval``)."""
    given = dict(A=A, B=B, C=C, D=D, x0=x0, sample_time=sample_time, state_units=state_units,
                 input_units=input_units, output_units=output_units, state_names=state_names,
                 input_names=input_names, output_names=output_names, description=description or None)
    return {"kind": "lti", **{k: _plain(v) for k, v in given.items() if v is not None}}


def _plain(value):
    """numpy arrays and scalars as lists and Python numbers (what the TOML writer takes)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def from_statespace(statespace, *, x0=None, description: str | None = None, **units) -> dict:
    """A python-control ``StateSpace`` as an ``lti`` component: its matrices, its sample time (a discrete
    system's ``dt``), and its state/input/output names, as ``state_names`` ... (FMU descriptions, summaries,
    figures; python-control's default labels ``x[0]`` ... are left out) and in the description
    (``x = [position, velocity]``).

    ``units``: ``state_units``, ``input_units``, ``output_units`` as for :func:`lti`.
    """
    for attribute in ("A", "B", "C", "D"):
        if not hasattr(statespace, attribute):
            raise ParameterError(f"statespace: {type(statespace).__name__} has no matrix {attribute}; "
                                 "expected a python-control StateSpace")
    dt = getattr(statespace, "dt", 0)
    if dt is True:
        raise ParameterError("statespace: a discrete system with an unspecified sample time (dt=True); "
                             "give it a sample time")
    names = [f"{label} = [{', '.join(getattr(statespace, attr))}]"
             for label, attr in (("x", "state_labels"), ("u", "input_labels"), ("y", "output_labels"))
             if getattr(statespace, attr, None)]
    text = description if description is not None else (getattr(statespace, "name", "") or "lti") + ": " + \
        "; ".join(names)
    given = {f"{kind}_names": list(labels) for kind, symbol, attr in
             (("state", "x", "state_labels"), ("input", "u", "input_labels"), ("output", "y", "output_labels"))
             if (labels := getattr(statespace, attr, None)) and list(labels) != [f"{symbol}[{i}]" for i in
                                                                               range(len(labels))]}
    return lti(np.asarray(statespace.A), np.asarray(statespace.B), np.asarray(statespace.C),
               np.asarray(statespace.D), x0=x0, sample_time=dt or None, description=text, **given, **units)


@dataclass
class System:
    """A system file built in Python: ``add`` components, ``connect`` ports, give ``values`` to inputs left
    unconnected, ``compare`` estimates with true states.  :meth:`toml` is the file it stands for."""

    name: str
    stop_time: float = 1.0
    step: float = 1e-3
    description: str = ""
    time_unit: str = "s"
    components: dict[str, dict] = field(default_factory=dict)
    connections: list[str] = field(default_factory=list)
    values: dict[str, object] = field(default_factory=dict)
    compares: list[dict] = field(default_factory=list)
    experiment: dict[str, object] = field(default_factory=dict)   #: more [experiment] fields

    def add(self, instance: str, component: dict | None = None, **fields) -> "System":
        """Add the component ``instance``: a dict (from :func:`lti`, :func:`from_statespace`) and/or
        fields (``kind="luenberger", plant="plant", poles=[-5, -6]``)."""
        if instance in self.components:
            raise ParameterError(f"components.{instance}: already added")
        self.components[instance] = {**(component or {}), **{k: _plain(v) for k, v in fields.items()}}
        return self

    def connect(self, source: str, target: str) -> "System":
        """``connect("plant.y", "observer.y")``."""
        self.connections.append(f"{source} -> {target}")
        return self

    def compare(self, estimate: str, truth: str, tolerance: float) -> "System":
        """A ``[[report.compare]]``: the summary reports when ``estimate`` stays within ``tolerance`` of ``truth``."""
        self.compares.append({"estimate": estimate, "truth": truth, "tolerance": float(tolerance)})
        return self

    def toml(self) -> str:
        """The system file's text."""
        data: dict = {"name": self.name, "time_unit": self.time_unit}
        if self.description:
            data["description"] = self.description
        data["connections"] = list(self.connections)
        data["experiment"] = {"stop_time": float(self.stop_time), "step": float(self.step), **self.experiment}
        data["components"] = self.components
        if self.values:
            data["values"] = {k: _plain(v) for k, v in self.values.items()}
        if self.compares:
            data["report"] = {"compare": self.compares}
        return dumps(data)

    def save(self, path: Path | str | None = None) -> Path:
        """Write the system file (default: into the cache, named by its content) and check it whole."""
        text = self.toml()
        if path is None:
            folder = _in.writable(cache_dir() / "systems", "OBSFMU_CACHE")
            path = folder / f"{self.name}-{hashlib.sha256(text.encode()).hexdigest()[:16]}.toml"
        path = Path(path)
        if not path.exists() or path.read_text() != text:
            path.write_text(text)
        _in.load_system(path)
        return path


def load(path: Path | str) -> Path:
    """Check the system file ``path`` whole (a :class:`ParameterError` names the line and field); returns it."""
    _in.scenario_from_file(path)
    return Path(path)


def scenarios() -> dict[str, str]:
    """The paper scenarios: name -> description."""
    return {name: s.description for name, s in _in.scenarios.SCENARIOS.items()}


def scenario(name: str) -> str:
    """The paper scenario ``name`` (checked), to give to :func:`run`, :func:`build` or :func:`export`."""
    _in.scenarios.get(name)
    return name


def _key(target) -> str:
    """The scenario key the internals know ``target`` by."""
    if isinstance(target, System):
        target = target.save()
    if isinstance(target, Path) or (isinstance(target, str) and target not in _in.scenarios.SCENARIOS):
        path = Path(target)
        if not path.is_file():
            raise ParameterError(f"{target}: neither a scenario ({', '.join(_in.scenarios.SCENARIOS)}) nor a "
                                 "system file")
        _in.scenario_from_file(path)
        return str(path.resolve())
    return target


def _build_dir(build_dir) -> Path:
    return Path(build_dir) if build_dir is not None else _in.writable(cache_dir() / "build", "OBSFMU_CACHE")


def _overrides(values: dict | None) -> list[tuple[str, str, float]]:
    overrides = []
    for name, value in (values or {}).items():
        instance, dot, variable = name.partition(".")
        if not dot or not variable:
            raise ParameterError(f"set: {name!r}: expected 'instance.variable'")
        if np.ndim(value):
            overrides += [(instance, f"{variable}[{i}]", float(v)) for i, v in enumerate(np.ravel(value), start=1)]
        else:
            overrides.append((instance, variable, float(value)))
    return overrides


# ----------------------------------------------------------------------------------------------- results

class Result:
    """A run: ``time`` (1-d array), ``columns`` (``plant.x[1]``, ...), ``values[k, j]`` (column j at time k),
    ``units`` (column -> declared unit), ``labels`` (column -> the name its plant gave the entry,
    ``state_names`` ..., where given), ``summary`` (the text ``obsfmu run`` prints, or ``""``) and ``metrics``
    (the numbers behind it)."""

    def __init__(self, raw, summary=None, labels=None):
        self._raw = raw
        self.labels: dict[str, str] = dict(labels or {})
        self.time: np.ndarray = raw.time
        self.columns: list[str] = list(raw.columns)
        self.values: np.ndarray = raw.values
        self.units: dict[str, str] = dict(raw.info.units) if raw.info else {}
        self.summary: str = str(summary) if summary else ""
        self.metrics: dict[str, float] = dict(summary.metrics) if summary else {}
        self.parameters: dict[str, float] = dict(raw.info.parameters) if raw.info else {}

    def __getitem__(self, column: str) -> np.ndarray:
        """One column (``"plant.y"``), or a whole port as ``(len(time), n)`` (``"plant.x"``)."""
        if column in self.columns:
            return self._raw[column]
        return self._raw.vector(column)

    def named_columns(self) -> list[str]:
        """The columns with the names their plants gave them: ``plant.x[1]`` -> ``plant.x.current``
        (``instance.port.name``; a column without a name, or whose name repeats in its port, as it is)."""
        named = [self._named(column) for column in self.columns]
        repeated = {name for name in named if named.count(name) > 1}
        return [column if name in repeated else name for column, name in zip(self.columns, named)]

    def _named(self, column: str) -> str:
        label = self.labels.get(column)
        return column if label is None else f"{column.partition('[')[0]}.{label}"

    def frame(self, names: bool = False):
        """The result as a pandas DataFrame indexed by time (pandas must be installed); ``names``: the columns
        as :meth:`named_columns` (``plant.x.current``), else as the FMUs name them (``plant.x[1]``)."""
        try:
            import pandas
        except ImportError:
            raise ImportError("Result.frame() needs pandas (pip install pandas); the arrays are "
                              "Result.time, Result.values and Result.columns") from None
        return pandas.DataFrame(self.values, index=pandas.Index(self.time, name="time"),
                                columns=self.named_columns() if names else self.columns)

    def to_csv(self, path: Path | str) -> None:
        self._raw.to_csv(path)

    def __repr__(self) -> str:
        return f"<obsfmu.Result {len(self.time)} points to t = {self.time[-1]:g}, {len(self.columns)} columns>"


def run(target, *, stop_time: float | None = None, step: float | None = None, set: dict | None = None,
        order: str | None = None, coupling: str | None = None, tolerance: float | None = None,
        fmi_version: int = 2, build_dir: Path | str | None = None, progress: bool = False) -> Result:
    """Build the FMUs (once, into the cache or ``build_dir``) and co-simulate ``target``.

    Parameters
    ----------
    target : System, path or str
        A :class:`System`, a system file, or a paper scenario's name (``"ship"``).
    stop_time, step, order, coupling, tolerance :
        As ``obsfmu run``'s options (None: the system's own).
    set : dict
        Start values, ``{"plant.x0[1]": 0.1, "observer.poles": [-10, -12]}`` (as ``--set``).
    """
    key = _key(target)
    raw, summary = _in.scenarios.run(key, _build_dir(build_dir), stop_time=stop_time, step=step, order=order,
                                     coupling=coupling, overrides=_overrides(set), progress=progress,
                                     tolerance=tolerance, fmi_version=fmi_version)
    return Result(raw, summary, _labels(_in.scenarios.get(key)))


def _labels(scenario) -> dict[str, str]:
    """Column -> name of the entries the scenario's plants named (``state_names`` ...)."""
    definitions = {d.model_name: d for d in (item[0] if isinstance(item, tuple) else item
                                             for item in scenario.definitions())}
    return _in.column_labels((instance, definitions[model]) for instance, model, _ in scenario.components
                             if model in definitions)


def build(target, out: Path | str | None = None, *, fmi_version: int = 2, standalone: bool = False,
          platforms=None) -> list[Path]:
    """Build the FMUs of ``target`` (as :func:`run`) into ``out`` (default: the cache); returns their paths."""
    key = _key(target)
    scenario_ = _in.scenarios.get(key)
    fmus = _in.scenarios.ensure_fmus(scenario_, _build_dir(out), fmi_version=fmi_version, standalone=standalone,
                                     platforms=platforms)
    return sorted(set(fmus.values()))


def export(target, fmt: str, out: Path | str, *, build_dir: Path | str | None = None, **options) -> Path:
    """Write ``target`` for another tool (``fmt``: ``ssp`` or ``osp``, as ``obsfmu export``); returns the file."""
    return _in.export(_in.scenarios.get(_key(target)), fmt, out, _build_dir(build_dir), **options)
