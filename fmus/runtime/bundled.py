"""The names of project modules inside the FMU that runs this code (the run-time half of :mod:`fmus.bundle`).

The builder relocates an FMU's code under ``_obsfmu_<hash>`` (:mod:`fmus.bundle`).  The two places
that import project modules by name -- :func:`fmus.runtime.callables.resolve` (``"plants.ltv:f_sin"``)
and :func:`fmus.runtime.kinds.create_block` (``kind_module``) -- map the name onto the FMU's own
package with :func:`local_name`.  Unrelocated (a checkout or an installed obsfmu) :data:`PACKAGE` is
``""`` and names stay as they are.
"""

from __future__ import annotations

import sys

__all__ = ["PACKAGE", "NAMES", "local_name", "portable_name"]

_OWN = "fmus.runtime.bundled"
#: the FMU's package (``"_obsfmu_<hash>"``) when this module runs relocated inside an FMU, else ""
PACKAGE = __name__[: -len(_OWN) - 1] if __name__.endswith("." + _OWN) else ""
#: attribute of the relocated package listing the bundled top-level names
NAMES = "BUNDLED"


def local_name(module: str) -> str:
    """The name under which ``module`` (e.g. ``"plants.ltv"``) is imported here."""
    if PACKAGE and module.split(".")[0] in getattr(sys.modules.get(PACKAGE), NAMES, ()):
        return f"{PACKAGE}.{module}"
    return module


def portable_name(module: str) -> str:
    """The inverse of :func:`local_name`: ``"_obsfmu_<hash>.plants.x"`` -> ``"plants.x"``."""
    prefix = PACKAGE + "."
    return module[len(prefix):] if PACKAGE and module.startswith(prefix) else module
