"""Everything the public API uses from the project's internals, imported in this one place.

When ``fmus``, ``observers`` and ``plants`` move under the ``obsfmu`` namespace, only these imports change.
"""

from fmus import scenarios
from fmus.caches import writable
from fmus.export import FORMATS, export
from fmus.master import SimulationError
from fmus.result import Result as RawResult
from fmus.system import load_system, scenario_from_file
from fmus.system.commands import build_definitions
from observers.checks import ParameterError

__all__ = ["scenarios", "writable", "FORMATS", "export", "SimulationError", "RawResult", "load_system",
           "scenario_from_file", "build_definitions", "ParameterError"]
