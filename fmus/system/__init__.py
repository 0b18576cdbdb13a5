"""Your own system in one TOML file: components, connections, experiment and report (issue 26).

``load_system(path)`` reads and checks a file into a :class:`~fmus.system.model.SystemSpec`;
``scenario_from_file(path)`` gives the :class:`~fmus.scenarios.Scenario` that ``obsfmu
run|build|export|sweep|report --config FILE`` run; ``field_reference()`` is the generated markdown of
``docs/system-file-reference.md``.  See docs/your-own-system.md and the design note of the layout.
"""

from __future__ import annotations

from pathlib import Path

from .load import load_system
from .model import SystemSpec

__all__ = ["load_system", "scenario_from_file", "resolve", "field_reference", "SystemSpec", "is_system_file"]

_CACHE: dict[tuple, object] = {}


def scenario_from_file(path: Path | str):
    """The scenario of the system file ``path``.

    Parameters
    ----------
    path : Path or str
        The system file; read once per content (cached by path, modification time and size).

    Returns
    -------
    fmus.scenarios.Scenario
        Added to :mod:`fmus.scenarios` under the file's resolved path, so that :func:`fmus.scenarios.get`
        (and with it run, export and the campaign) finds it in this process.

    Raises
    ------
    ParameterError
        Any mistake of the file (:func:`fmus.system.load.parse_system`).
    """
    from .. import scenarios
    path = Path(path)
    try:
        stat = path.stat()
        key = (str(path.resolve()), stat.st_mtime_ns, stat.st_size)
    except OSError:
        return load_system(path).scenario()          # it says why the file cannot be read
    if key not in _CACHE:
        _CACHE[key] = load_system(path).scenario()
    scenarios.add(key[0], _CACHE[key])
    return _CACHE[key]


def resolve(name: str):
    """The scenario ``name``: a paper scenario's name, or a system file's path (read and added if needed).

    Parameters
    ----------
    name : str
        ``"ship"``, or ``"/home/me/dcmotor.toml"`` (what a sweep's tasks carry to their workers).

    Returns
    -------
    fmus.scenarios.Scenario
    """
    from .. import scenarios
    known = name in scenarios.SCENARIOS or scenarios.is_added(name)
    return scenarios.get(name) if known or not is_system_file(name) else scenario_from_file(name)


def is_system_file(name: str) -> bool:
    """``name`` is a path to something readable that is not a folder (a file, or a pipe: ``<(obsfmu show ...)``)."""
    path = Path(name)
    return path.exists() and not path.is_dir()


def field_reference() -> str:
    """The field reference of the system file (markdown), generated from the registry."""
    from obsfmu.observers.expressions import MAX_DEPTH, MAX_LENGTH

    from .connect import MAX_CONNECTIONS
    from .load import COMPARE_FIELDS, EXPERIMENT_FIELDS, MAX_COMPONENTS, MAX_FILE_BYTES, TOP_FIELDS
    from .kinds import reference
    from .values import MAX_DIMENSION, MAX_ENTRIES, MAX_TEXT
    from ..master.session import MAX_POINTS
    from obsfmu.plants.sources.tables import CsvColumn
    limits = (f"A file of at most {MAX_FILE_BYTES // 2 ** 20} MiB, plain UTF-8 text without control characters; "
              f"at most {MAX_COMPONENTS} components and {MAX_CONNECTIONS} connections; matrices of at most "
              f"{MAX_DIMENSION} rows and columns (states, inputs, outputs), vectors of at most {MAX_ENTRIES} "
              f"entries; texts of at most {MAX_TEXT} characters; an expression of at most {MAX_LENGTH} characters "
              f"nested at most {MAX_DEPTH} deep; a run of at most {MAX_POINTS:.0e} communication points "
              f"(stop_time / step with any master but the adaptive one; --step and --stop-time too); a `csv` "
              f"source's file of at most {CsvColumn.MAX_BYTES // 2 ** 20} MiB. Beyond a limit the file is refused at "
              "once, naming the field and the limit.")
    return reference({
        "Top level": ("The file's own fields, before any table.", TOP_FIELDS),
        "[experiment]": ("The run's defaults (`obsfmu run` options override them).", EXPERIMENT_FIELDS),
        "[values]": ("`\"component.input\" = number` (or a list for a whole port, or `component.input[i]`): "
                     "the value of an input deliberately left unconnected. Every input is connected or given "
                     "here.", ()),
        "[[report.compare]]": ("What the summary and the figure compare (one table per pair). `[report]` may "
                               "also name `reference = \"file.csv\"`: a CSV of the run's columns to compare with.",
                               COMPARE_FIELDS),
        "[plot]": ("What else the figure draws: `signals = [\"reference.y\", \"plant.x[2]\"]`, a panel per output "
                   "(or element), with its units and names, beside the comparisons.", ()),
        "Limits": (limits, ()),
    })
