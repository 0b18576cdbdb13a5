"""obsfmu from Python: build or load a system, run it, get arrays; build and export its FMUs.

>>> import obsfmu
>>> system = obsfmu.System("motor", stop_time=1.0, step=1e-3)
>>> system.add("plant", obsfmu.lti(A=[[0, 1], ["-16000/250", -2]], B=[[0], [1]], C=[[1, 0]]))
>>> system.values["plant.u"] = 1.0
>>> result = obsfmu.run(system)
>>> result.time, result["plant.y"], result.units

The API lives in :mod:`obsfmu.api` and is imported on first use (``obsfmu.run``), so the command line
and the FMU code under this package do not pay for it.  The project's own packages are installed under
this one: :mod:`obsfmu.fmus` (the FMI layer), :mod:`obsfmu.observers` (the algorithms, no FMI),
:mod:`obsfmu.plants` (plant models).  See docs/python.md.
"""

from __future__ import annotations

from importlib import import_module
from importlib.metadata import PackageNotFoundError, version as _distribution_version

#: the project's packages installed under this one (``obsfmu.fmus``, ``obsfmu.observers``, ``obsfmu.plants``):
#: :func:`obsfmu.fmus.runtime.bundled.local_name` maps portable module names (``"plants.ltv:f_sin"``) onto
#: them here, as it maps them onto an FMU's own package inside an FMU
BUNDLED = ("fmus", "observers", "plants")

try:
    __version__ = _distribution_version("obsfmu")
except PackageNotFoundError:          # a checkout that was not installed
    __version__ = "unknown"

__all__ = ["System", "Result", "lti", "from_statespace", "load", "run", "build", "export", "scenario",
           "scenarios", "ParameterError", "SimulationError", "cache_dir", "BUNDLED", "__version__"]


def __getattr__(name: str):
    """The public API, imported from :mod:`obsfmu.api` on first use (PEP 562)."""
    if name in __all__:
        return getattr(import_module(".api", __name__), name)
    raise AttributeError(f"module 'obsfmu' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
