"""FMI 3.0 co-simulation FMUs from the same definitions as the FMI 2.0 ones (docs/fmi3.md).

One definition (:class:`~fmus.runtime.definition.FmuDefinition`), one slave (:class:`fmus.runtime.slave.BlockSlave`,
the same Python behaviour), two front ends:

* FMI 2.0: pythonfmu's description of the slave, scalar variables ``x_hat[1]``, ``A[1,2]``;
* FMI 3.0: :mod:`fmus.fmi3.description` writes ``modelDescription.xml`` with array variables
  (``x_hat`` of size n, ``A`` of n x n) whose elements are those scalars, and the table the FMI 3.0
  loader (``fmus/native/loader_fmi3.c``) translates value references with.

An FMI 3.0 FMU has the FMI 2.0 FMU's resources (definition, bundled code, bridge) plus that table;
its binaries are in ``binaries/<platform tuple>/`` (``x86_64-linux``).  Built FMI 3.0 FMUs live in the
sub-folder ``fmi3/`` of a build directory (:func:`build_folder`), beside the FMI 2.0 FMUs of the
same names.
"""

from __future__ import annotations

import platform
import sys
from pathlib import Path

__all__ = ["VERSIONS", "check_version", "platform_tuple", "build_folder", "TABLE"]

#: FMI versions an FMU can be built for
VERSIONS = (2, 3)
#: the FMI 3.0 loader's variable table, in resources/ (fmus/fmi3/description.py writes it)
TABLE = "obsfmu_fmi3.txt"


def check_version(fmi_version) -> int:
    """``fmi_version`` as an int, or a ValueError naming the parameter."""
    if fmi_version not in VERSIONS:
        raise ValueError(f"fmi_version: {fmi_version!r} is not one of {VERSIONS}")
    return int(fmi_version)


def platform_tuple() -> str:
    """FMI 3.0 name of this platform's binaries folder (``x86_64-linux``, ``aarch64-darwin``)."""
    machine = {"amd64": "x86_64", "arm64": "aarch64"}.get(platform.machine().lower(), platform.machine().lower())
    if sys.platform.startswith("linux"):
        return f"{machine}-linux"
    if sys.platform == "darwin":
        return f"{machine}-darwin"
    raise RuntimeError(f"platform {sys.platform!r}: building FMU binaries is supported on Linux and macOS")


def build_folder(build_dir, fmi_version: int = 2) -> Path:
    """Where FMUs of ``fmi_version`` are built: ``build_dir`` (FMI 2.0) or ``build_dir/fmi3`` (FMI 3.0)."""
    return Path(build_dir) if check_version(fmi_version) == 2 else Path(build_dir) / "fmi3"
