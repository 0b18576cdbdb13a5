"""Everything the public API uses from the project's internals, imported in this one place.

When ``fmus``, ``observers`` and ``plants`` move under the ``obsfmu`` namespace, only these imports change.
"""

from obsfmu.fmus import scenarios
from obsfmu.fmus.caches import obsfmu_cache, writable
from obsfmu.fmus.export import FORMATS, export
from obsfmu.fmus.master import SimulationError
from obsfmu.fmus.result import Result as RawResult
from obsfmu.fmus.runtime.definition import column_labels
from obsfmu.fmus.system import load_system, scenario_from_file
from obsfmu.fmus.system.commands import build_definitions
from obsfmu.observers.checks import ParameterError

__all__ = ["scenarios", "obsfmu_cache", "writable", "FORMATS", "export", "SimulationError", "RawResult", "load_system",
           "scenario_from_file", "build_definitions", "ParameterError", "column_labels"]
