"""The native binaries of every obsfmu FMU, compiled on demand and cached per machine.

An FMU carries two shared objects (design and limits: ``docs/portability.md``):

* the **loader** (``loader.c``), the FMU's ``binaries/<platform>/<model>.so``: plain C with no
  Python symbols, so it loads in any FMI importer; it enforces the FMI 2.0 state machine and
  finds Python: the interpreter already running in the process, or the one recorded when the FMU
  was built (``resources/obsfmu_native.txt``, see :func:`python_record`), or the one named by
  ``$OBSFMU_PYTHON``, started once per process;
* the **bridge** (``bridge.c``): the FMI calls -> the Python slave, compiled against the Python
  headers of the interpreter that builds the FMU (that Python version runs it).

Both are compiled with the C compiler (``$CC`` or ``cc``; FMI headers from fmpy) and cached in
``$XDG_CACHE_HOME/obsfmu/native`` (default ``~/.cache/obsfmu/native``) under a key of their
sources, flags and -- for the bridge -- the Python version and headers (a cache that cannot be written: a
private temporary one, :mod:`fmus.caches`).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from dataclasses import dataclass
from pathlib import Path

from ..caches import cache_root, writable

__all__ = ["NativeBuildError", "Target", "TARGETS", "target", "host", "platform_folder", "fmi_headers", "compiled",
           "loader_library", "bridge_library", "kernel_library", "bridge_name", "python_record", "identity", "BOOTSTRAP", "OVERRIDE",
           "STARTS"]

HERE = Path(__file__).parent
LOADER, BRIDGE = HERE / "loader.c", HERE / "bridge.c"
#: the FMI 3.0 loader (same bridge, same Python rules; docs/fmi3.md)
LOADER_FMI3 = HERE / "loader_fmi3.c"
#: what the sources include (obsfmu_native.h, loader_common.h, win64/pyconfig.h): part of every cache key
HEADERS = tuple(sorted(HERE.glob("*.h"))) + tuple(sorted(HERE.glob("win64/*.h")))
#: run by the bridge at each instantiation to import the FMU's own code (copied into resources/)
BOOTSTRAP = HERE / "bootstrap.py"
#: environment variable pointing an FMU at another Python installation (read by the loader)
OVERRIDE = "OBSFMU_PYTHON"
#: start values an exported FMU copy sets itself (resources/, read by loader_common.h; fmus/export.py)
STARTS = "obsfmu_start.txt"


class NativeBuildError(RuntimeError):
    """The FMU binary could not be compiled; the message says what is missing."""


@dataclass(frozen=True)
class Target:
    """A platform the FMU binaries are compiled for (``obsfmu build --platform``)."""

    name: str                 #: the FMI 2.0 binaries folder: ``linux64``, ``win64``, ``darwin64``
    fmi3_folder: str          #: the FMI 3.0 binaries folder (platform tuple): ``x86_64-linux``, ...
    suffix: str               #: of its shared libraries: ``.so``, ``.dll``, ``.dylib``
    shared: tuple[str, ...]   #: compiler flags for a shared library
    loader: tuple[str, ...]   #: and for the loaders (no Python in them)

    def compiler(self) -> list[str]:
        """The C compiler command for this target (``$CC`` or cc for the host; MinGW-w64 for win64)."""
        if self.name == "win64":
            command = os.environ.get("OBSFMU_MINGW_CC") or shutil.which(MINGW)
            if not command:
                raise NativeBuildError(f"a win64 FMU needs the MinGW-w64 cross compiler {MINGW} (Debian: apt-get install "
                                       "mingw-w64; or set OBSFMU_MINGW_CC) -- only to build, never to run")
            return [command]
        if self is not host():
            raise NativeBuildError(f"--platform {self.name}: FMU binaries for {self.name} are built on {self.name} "
                                   f"itself (this is {platform_folder()}); win64 is cross-compiled from Linux")
        return [_compiler()]


#: MinGW-w64's C compiler (the win64 binaries; tests run them under wine)
MINGW = "x86_64-w64-mingw32-gcc"
_UNIX_SHARED = ("-shared", "-fPIC", "-O2", "-Wall", "-fvisibility=hidden", "-ffp-contract=off")
# -ffp-contract=off: no fused multiply-add, so the step kernels (kernel.h, the compiled expressions) do numpy's and
# Python's operations one by one, to the bit.  snprintf may truncate over-long paths on purpose (they then do not
# exist): no warning for that
TARGETS = {
    "linux64": Target("linux64", "x86_64-linux", ".so", _UNIX_SHARED,
                      ("-pthread", "-ldl", "-Wno-format-truncation", "-Wl,-Bsymbolic")),
    "darwin64": Target("darwin64", "x86_64-darwin", ".dylib", _UNIX_SHARED, ("-pthread", "-Wno-format-truncation")),
    # static libgcc and winpthreads: the DLLs need nothing but KERNEL32 and msvcrt (and the bridge python3X.dll)
    "win64": Target("win64", "x86_64-windows", ".dll", ("-shared", "-O2", "-Wall", "-static-libgcc", "-ffp-contract=off"),
                    ("-pthread", "-static", "-Wno-format-truncation")),
}


def target(name: str) -> Target:
    """The :class:`Target` of a platform name (``linux64``, ``win64``, ``darwin64``)."""
    if name not in TARGETS:
        raise NativeBuildError(f"platform {name!r} is not one of {', '.join(TARGETS)}")
    return TARGETS[name]


def host() -> Target:
    """The platform this machine builds for natively."""
    return TARGETS[platform_folder()]


def platform_folder() -> str:
    """FMI 2.0 name of the binaries folder of this platform."""
    if sys.platform.startswith("linux"):
        return "linux64" if sys.maxsize > 2**32 else "linux32"
    if sys.platform == "darwin":
        return "darwin64"
    raise NativeBuildError(f"platform {sys.platform!r}: building FMU binaries is supported on Linux and macOS")


def fmi_headers() -> Path:
    """The FMI 2.0 and 3.0 C headers (shipped with fmpy)."""
    import fmpy
    headers = Path(fmpy.__file__).parent / "c-code"
    if not all((headers / name).is_file() for name in ("fmi2Functions.h", "fmi3Functions.h")):
        raise NativeBuildError(f"FMI 2/3 headers not found in {headers} (fmpy installation incomplete)")
    return headers


def _compiler() -> str:
    compiler = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if not compiler:
        raise NativeBuildError("no C compiler found (install gcc, or set CC) -- needed once to build FMU binaries")
    return compiler


def cache_dir() -> Path:
    """Where the compiled binaries are cached (``$XDG_CACHE_HOME/obsfmu/native``)."""
    return cache_root() / "native"


def compiled(stem: str, source: Path, flags: list[str], key_material: str, target: Target | None = None) -> Path:
    """``source`` compiled for ``target`` (default: this machine) with ``flags`` into a shared library in the
    cache (once per key: the sources, the flags, ``key_material``), atomically."""
    target = target or host()
    key = hashlib.sha256(source.read_bytes() + b"".join(h.read_bytes() for h in HEADERS) + " ".join(flags).encode()
                         + key_material.encode() + target.name.encode()).hexdigest()[:16]
    name = f"{stem}-{key}{target.suffix}"
    found = cache_dir() / name
    if found.is_file():
        return found
    folder = writable(cache_dir(), "XDG_CACHE_HOME")   # to be compiled: into a cache that can be written
    if (folder / name).is_file():
        return folder / name
    with tempfile.TemporaryDirectory(dir=folder) as temp:
        output = Path(temp) / name
        command = [*target.compiler(), *target.shared, "-o", str(output), str(source), f"-I{HERE}",
                   f"-I{fmi_headers()}", *flags]
        completed = subprocess.run(command, capture_output=True, text=True)
        if completed.returncode != 0:
            raise NativeBuildError("compiling the FMU binary failed:\n" + " ".join(command) + "\n"
                                   + completed.stderr)
        os.replace(output, folder / name)  # atomic: concurrent builds never see a partial file
    return folder / name


def loader_library(fmi_version: int = 2, platform: str | None = None) -> Path:
    """The loader of FMI ``fmi_version`` (2 or 3) for ``platform`` (default: this machine's; no Python in it: one
    binary serves every Python version)."""
    if fmi_version not in (2, 3):
        raise NativeBuildError(f"fmi_version: {fmi_version!r} is not 2 or 3")
    chosen = target(platform) if platform else host()
    if fmi_version == 3:
        return compiled("obsfmu_loader_fmi3", LOADER_FMI3, list(chosen.loader), chosen.name, chosen)
    return compiled("obsfmu_loader", LOADER, list(chosen.loader), chosen.name, chosen)


def bridge_library(platform: str | None = None) -> Path:
    """The bridge for this interpreter's Python version (compiled against its headers), for ``platform``
    (default: this machine's; win64's is :func:`fmus.native.windows.bridge_library`, chosen by the builder)."""
    if platform and target(platform) is not host():
        raise NativeBuildError(f"--platform {platform}: its bridge is built on {platform} itself")
    include = sysconfig.get_paths()["include"]
    if not (Path(include) / "Python.h").is_file():
        raise NativeBuildError(f"Python.h not found in {include} (install the Python development headers, "
                               f"e.g. python{_version()}-dev)")
    flags = [f"-I{include}"] + (["-undefined", "dynamic_lookup"] if sys.platform == "darwin" else [])
    return compiled(f"obsfmu_bridge_cp{_version().replace('.', '')}", BRIDGE, flags, include + sys.version)


def kernel_library(source: str, platform: str | None = None) -> Path:
    """An FMU's own kernel library -- ``source``, the C of its compiled expressions
    (:func:`fmus.runtime.slave.kernel.kernel_source`) -- for ``platform`` (default: this machine's), compiled once
    per source (cached)."""
    chosen = target(platform) if platform else host()
    folder = writable(cache_dir(), "XDG_CACHE_HOME")
    path = folder / f"obsfmu_kernel-{hashlib.sha256(source.encode()).hexdigest()[:16]}.c"
    if not path.is_file():
        with tempfile.NamedTemporaryFile("w", dir=folder, suffix=".partial", delete=False) as file:
            file.write(source)
        os.replace(file.name, path)
    return compiled("obsfmu_kernel", path, [] if chosen.name == "win64" else ["-lm"], "", chosen)


def bridge_name(platform: str | None = None) -> str:
    """File name of the bridge inside an FMU's binaries folder."""
    return f"obsfmu_bridge_cp{_version().replace('.', '')}{(target(platform) if platform else host()).suffix}"


def _version() -> str:
    return f"{sys.version_info.major}.{sys.version_info.minor}"


def _libpython() -> str:
    """The shared libpython of this interpreter, or "" when it has none (a statically linked Python)."""
    get = sysconfig.get_config_var
    version = _version() + (getattr(sys, "abiflags", "") or "")
    names = [get("INSTSONAME") or ""] + [f"libpython{version}{s}" for s in (".so.1.0", ".so.1", ".so", ".dylib")]
    folders = [get("LIBDIR") or "", os.path.join(get("LIBDIR") or "", get("MULTIARCH") or ""), get("LIBPL") or ""]
    for folder in filter(None, folders):
        for name in filter(None, names):
            path = os.path.join(folder, name)
            if not name.endswith(".a") and os.path.isfile(path):
                return path
    return ""


def python_record() -> dict[str, str]:
    """What the loader needs to start this Python in a process without one (under ``env -i``)."""
    executable = os.path.abspath(sys.executable) if sys.executable else ""
    return {"python_version": _version(), "python_executable": executable, "python_library": _libpython(),
            "python_multiarch": sysconfig.get_config_var("MULTIARCH") or ""}


def identity() -> str:
    """Everything about the binaries an FMU depends on: their sources and the recorded Python."""
    sources = b"".join(path.read_bytes() for path in (LOADER, LOADER_FMI3, BRIDGE, *HEADERS, BOOTSTRAP))
    return hashlib.sha256(sources).hexdigest() + repr(sorted(python_record().items())) + sys.version
