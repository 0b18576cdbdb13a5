"""The native FMI 2.0 binary of every obsfmu FMU, compiled on demand.

``obsfmu_fmi2.c`` forwards the FMI C API to the generic Python slave
(:mod:`fmus.slave`) running in the importer's Python interpreter.  It is
compiled once per machine and Python version with the C compiler (``cc`` or
``$CC``) against the Python headers and the FMI 2 headers shipped with fmpy,
and cached in ``$XDG_CACHE_HOME/obsfmu`` (default ``~/.cache/obsfmu``).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from pathlib import Path

__all__ = ["SOURCE", "NativeBuildError", "platform_folder", "shared_library"]

SOURCE = Path(__file__).with_name("obsfmu_fmi2.c")


class NativeBuildError(RuntimeError):
    """The FMU binary could not be compiled; the message says what is missing."""


def platform_folder() -> str:
    """FMI 2.0 name of the binaries folder of this platform."""
    if sys.platform.startswith("linux"):
        return "linux64" if sys.maxsize > 2**32 else "linux32"
    if sys.platform == "darwin":
        return "darwin64"
    raise NativeBuildError(f"platform {sys.platform!r}: building FMU binaries is supported on Linux and macOS")


def _fmi_headers() -> Path:
    import fmpy
    headers = Path(fmpy.__file__).parent / "c-code"
    if not (headers / "fmi2Functions.h").is_file():
        raise NativeBuildError(f"FMI 2 headers not found in {headers} (fmpy installation incomplete)")
    return headers


def _compiler() -> str:
    compiler = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if not compiler:
        raise NativeBuildError("no C compiler found (install gcc, or set CC) -- needed once to build FMU binaries")
    return compiler


def _cache_dir() -> Path:
    root = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return root / "obsfmu" / "native"


def shared_library() -> Path:
    """Path of the compiled binary for this interpreter (compiled on first use)."""
    python_include = sysconfig.get_paths()["include"]
    if not (Path(python_include) / "Python.h").is_file():
        raise NativeBuildError(f"Python.h not found in {python_include} (install the Python development headers)")
    headers = _fmi_headers()
    suffix = ".dylib" if sys.platform == "darwin" else ".so"
    key = hashlib.sha256(SOURCE.read_bytes() + python_include.encode() + sys.version.encode()).hexdigest()[:16]
    target = _cache_dir() / f"obsfmu_fmi2-{key}{suffix}"
    if target.is_file():
        return target
    target.parent.mkdir(parents=True, exist_ok=True)
    flags = ["-undefined", "dynamic_lookup"] if sys.platform == "darwin" else []
    with tempfile.TemporaryDirectory(dir=target.parent) as temp:
        output = Path(temp) / target.name
        command = [_compiler(), "-shared", "-fPIC", "-O2", "-Wall", "-o", str(output), str(SOURCE),
                   f"-I{python_include}", f"-I{headers}", *flags, "-ldl"]
        completed = subprocess.run(command, capture_output=True, text=True)
        if completed.returncode != 0:
            raise NativeBuildError("compiling the FMU binary failed:\n" + " ".join(command) + "\n"
                                   + completed.stderr)
        os.replace(output, target)  # atomic: concurrent builds never see a partial file
    return target
