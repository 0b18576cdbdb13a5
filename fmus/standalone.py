"""Standalone FMUs (``obsfmu build --standalone``): the FMU carries the Python runtime it runs on.

The runtime goes into ``resources/python/`` (layout and reasons: ``docs/portability.md``)::

    lib/libpython3.X.so.1.0                  the building interpreter's shared libpython
    lib/<soname>                             every other shared library they load that is not in the
                                             manylinux2014 system set (SYSTEM_LIBRARIES), e.g. libffi
    lib/python3.X/...                        the standard library modules the FMU's code imports, as
                                             sourceless .pyc (unchecked hash: valid wherever unzipped),
                                             and the lib-dynload extensions among them
    lib/python3.X/site-packages/...          numpy (and any other installed package the code imports):
                                             the modules imported, their extension modules, <pkg>.libs/
    obsfmu_runtime.txt                       what is in it, for people

What "imports" means is measured, not guessed: the FMU's slave is run in a subprocess of the building
Python (``python -I -S``, :mod:`fmus.standalone_trace`) the way the bridge runs it -- instantiated,
initialized, stepped, its state saved and restored, a call refused, reset -- and every module in
``sys.modules`` at the end is bundled.  The shared libraries follow from ``ldd`` on every bundled
``.so``.  The record (``resources/obsfmu_native.txt``) gets ``runtime``, ``runtime_library``,
``runtime_preload`` (the bundled libraries in dependency order: the loader ``dlopen``\\ s them before
libpython, so the extensions that need them find them by soname) and ``runtime_path`` (the module
search path, relative to the runtime); the loader starts that interpreter isolated
(``PyConfig_InitIsolatedConfig``) in a process without Python.
"""

from __future__ import annotations

import functools
import importlib.util
import marshal
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import zipfile
from pathlib import Path

from . import native
from .native.bootstrap import RUNTIME_DESCRIPTION
from .native.bytecode import sourceless

__all__ = ["StandaloneError", "with_runtime", "runtime_files", "compiled_bundle", "sourceless", "identity", "describe",
           "SYSTEM_LIBRARIES", "RUNTIME"]

#: the folder of the runtime inside resources/
RUNTIME = "python"
#: shared libraries every Linux target has (manylinux2014's system set, as the issue names it): never bundled
SYSTEM_LIBRARIES = ("libc.so", "libm.so", "libdl.so", "librt.so", "libpthread.so", "libgcc_s.so", "libstdc++.so",
                    "ld-linux", "linux-vdso")
_VERSION = f"python{sys.version_info.major}.{sys.version_info.minor}"
_STDLIB = f"lib/{_VERSION}"
_SITE = f"{_STDLIB}/site-packages"
#: the module search path of the runtime, relative to it (read by the bridge from the record)
SEARCH_PATH = (_STDLIB, f"{_STDLIB}/lib-dynload", _SITE)
_LDD = re.compile(r"^\s*(\S+)\s+=>\s+(\S+)\s+\(0x[0-9a-f]+\)\s*$")


class StandaloneError(native.NativeBuildError):
    """The runtime of a standalone FMU cannot be assembled; the message says why."""


def _system(name: str) -> bool:
    return name.startswith(SYSTEM_LIBRARIES)


def _sites() -> list[str]:
    """The building interpreter's site-packages folders (venv, system, user), in its search order."""
    return list(dict.fromkeys(p for p in sys.path if Path(p).name in ("site-packages", "dist-packages")))


def traced_modules(resources: Path) -> dict[str, Path]:
    """module name -> file of every module the FMU unpacked (its resources) in ``resources`` imports."""
    command = [sys.executable, "-I", "-S", "-X", "utf8", str(Path(__file__).with_name("standalone_trace.py")),
               str(resources), *_sites()]
    keep = {key: os.environ[key] for key in ("LD_LIBRARY_PATH",) if key in os.environ}  # where libpython may be
    completed = subprocess.run(command, capture_output=True, text=True, env=keep, timeout=600)
    if completed.returncode != 0:
        raise StandaloneError("running the FMU's slave to see what it imports failed:\n"
                              + completed.stderr[-3000:])
    return {name: Path(origin) for name, origin in (line.split("\t", 1) for line in completed.stdout.splitlines())}


def _placed(path: Path) -> tuple[str | None, Path | None]:
    """Where a module file of the building Python goes in the runtime (relative to it; None if it is not
    the standard library's or an installed package's) and, for a package's, its top-level folder."""
    path = path.resolve()
    for site in map(Path, _sites()):
        if path.is_relative_to(site.resolve()):
            relative = path.relative_to(site.resolve())
            return f"{_SITE}/{relative.as_posix()}", site / relative.parts[0]
    stdlib = Path(sysconfig.get_paths()["stdlib"]).resolve()
    if path.is_relative_to(stdlib) and "site-packages" not in path.relative_to(stdlib).parts:
        return f"{_STDLIB}/{path.relative_to(stdlib).as_posix()}", None
    return None, None


@functools.lru_cache(maxsize=4096)
def _sourceless(source: Path, name: str) -> bytes:
    return sourceless(source.read_bytes(), name)


def _module_files(modules: dict[str, Path], resources: Path) -> tuple[dict[str, bytes | Path], set[Path]]:
    """The runtime's module files (relative name -> .pyc bytes or a .so to copy) and the site-packages
    top-level folders they come from."""
    files: dict[str, bytes | Path] = {}
    tops: set[Path] = set()
    outside = []
    for name, path in modules.items():
        if path.is_relative_to(resources) or name == "__main__":
            continue  # the FMU's own code (resources/_obsfmu_<hash>) and the trace script
        placed, top = _placed(path)
        if placed is None:
            outside.append(f"{name} ({path})")
            continue
        if top is not None:
            tops.add(top)
        if path.suffix == ".py":
            files[placed[:-3] + ".pyc"] = _sourceless(path, placed)
        elif path.suffix == ".so":
            files[placed] = path
        else:
            outside.append(f"{name} ({path}: neither .py nor .so)")
    if outside:
        raise StandaloneError("the FMU's code imports modules that are neither in the standard library nor in "
                              "an installed package, which a standalone FMU cannot carry: " + ", ".join(outside))
    return files, tops


def _libraries_folders(tops: set[Path]) -> dict[str, Path]:
    """The ``<package>.libs`` folders (auditwheel's: numpy's openblas) of the installed packages used."""
    files = {}
    for top in tops:
        libs = top.with_name(top.name + ".libs")
        if libs.is_dir():
            files.update({f"{_SITE}/{libs.name}/{so.name}": so for so in sorted(libs.iterdir()) if so.is_file()})
    return files


def _ldd(library: Path) -> dict[str, Path]:
    """soname -> resolved path of every shared library ``library`` loads (transitively), per ``ldd``."""
    completed = subprocess.run(["ldd", str(library)], capture_output=True, text=True)
    if completed.returncode != 0:
        raise StandaloneError(f"ldd {library} failed: {completed.stderr.strip() or completed.stdout.strip()}")
    found = {}
    for line in completed.stdout.splitlines():
        if "not found" in line:
            raise StandaloneError(f"{library} needs {line.split()[0]}, which is not found on this machine")
        match = _LDD.match(line)
        if match:
            found[match[1]] = Path(match[2])
    return found


def _dependencies(files: dict[str, bytes | Path]) -> tuple[dict[str, Path], list[str]]:
    """The non-system shared libraries the runtime's ``.so`` files load that it does not hold already
    (``lib/<soname>`` -> file) and their preload order (dependencies first)."""
    held = {path.resolve() for path in files.values() if isinstance(path, Path)}
    extra: dict[str, Path] = {}
    for path in [p for p in files.values() if isinstance(p, Path)]:
        for soname, resolved in _ldd(path).items():
            if not _system(soname) and resolved.resolve() not in held:
                extra[f"lib/{soname}"] = resolved
    # each library's bundled dependencies (ldd is transitive): one with more of them loads later
    depends = {name: sum(f"lib/{s}" in extra for s in _ldd(path)) for name, path in extra.items()}
    return extra, sorted(extra, key=lambda name: (depends[name], name))


@functools.lru_cache(maxsize=256)
def _without_debug_information(library: Path) -> bytes | Path:
    """``library`` without its debug sections (``strip --strip-debug``: symbols kept; pyenv builds
    libpython with ``-g``, 23 -> 6 MB), or the file itself when there is no ``strip``."""
    strip = shutil.which("strip")
    if strip is None:
        return library
    with tempfile.TemporaryDirectory(prefix="obsfmu_strip_") as temp:
        target = Path(temp) / library.name
        completed = subprocess.run([strip, "--strip-debug", "-o", str(target), str(library)], capture_output=True)
        return target.read_bytes() if completed.returncode == 0 else library


def _stripped(files: dict[str, bytes | Path]) -> dict[str, bytes | Path]:
    """``files`` with the interpreter's own libraries (all but the installed packages') stripped of debug
    information (an installed package's wheel ships them stripped already)."""
    return {name: _without_debug_information(data) if isinstance(data, Path) and not name.startswith(_SITE + "/")
            else data for name, data in files.items()}


def compiled_bundle(files: dict[str, bytes]) -> dict[str, bytes]:
    """The bytecode of the FMU's own code (``resources/_obsfmu_<hash>/...``): a sourceless-style, unchecked
    ``__pycache__/<module>.<cache tag>.pyc`` beside each ``.py``, used by the runtime the FMU carries (the
    building Python's minor version, on Linux and Windows alike) instead of compiling the code at the first
    instantiation -- nothing can be written into an unzipped FMU.  Another Python (a host of another version)
    ignores them (another cache tag)."""
    tag = sys.implementation.cache_tag
    compiled = {}
    for name, data in files.items():
        if name.startswith("resources/_obsfmu_") and name.endswith(".py"):
            folder, _, file = name.rpartition("/")
            compiled[f"{folder}/__pycache__/{file[:-3]}.{tag}.pyc"] = sourceless(data, name)
    return compiled


def runtime_files(resources: Path, modules: dict[str, Path] | None = None
                  ) -> tuple[dict[str, bytes | Path], dict[str, str]]:
    """The files of ``resources/python/`` (relative to it: bytes, or a file to copy) for the FMU whose
    resources are unpacked in ``resources`` and whose code imports ``modules`` (default: traced here), and the
    record's ``runtime*`` values."""
    library = native.python_record()["python_library"]
    if not library:
        raise StandaloneError(f"{sys.executable} has no shared libpython: a standalone FMU needs one "
                              "(a Python built with --enable-shared)")
    if not sys.platform.startswith("linux"):
        raise StandaloneError(f"standalone FMUs are built on Linux only (this is {sys.platform})")
    modules = traced_modules(resources) if modules is None else modules
    files, tops = _module_files(modules, resources.resolve())
    files.update(_libraries_folders(tops))
    libpython = Path(library).resolve()
    files[f"lib/{Path(library).name}"] = libpython
    extra, preload = _dependencies(files)
    files.update(extra)
    if any(" " in name for name in preload):
        raise StandaloneError(f"shared library names with spaces cannot be preloaded: {preload}")
    record = {"runtime": RUNTIME, "runtime_library": f"lib/{Path(library).name}",
              "runtime_preload": " ".join(preload), "runtime_path": ":".join(SEARCH_PATH)}
    files = _stripped(files)
    files[RUNTIME_DESCRIPTION] = _description(sys.version.split()[0], modules, record).encode()
    return files, record


def _description(version: str, modules: dict, record: dict) -> str:
    return (f"# obsfmu standalone runtime (fmus/standalone.py, docs/portability.md): Python {version}\n"
            + record_lines(record)
            + f"# {len(modules)} modules imported by the FMU's code at run time:\n"
            + "".join(f"#   {name}\n" for name in sorted(modules)))


def with_runtime(files: dict[str, bytes], record_name: str, linux: bool = True, win64: bool = False
                 ) -> dict[str, bytes | Path]:
    """An FMU's ``files`` (archive name -> bytes, as the builder assembles them) with the runtimes it carries:
    ``linux``, this machine's in ``resources/python/``; ``win64``, the Windows one in ``resources/python-win64/``
    (:mod:`fmus.native.windows`) -- and their keys appended to its record ``record_name``.  What the code
    imports is traced once for both."""
    amended, record = dict(files), {}
    with tempfile.TemporaryDirectory(prefix="obsfmu_standalone_") as temp:
        root = Path(temp)
        for name, data in files.items():
            if name.startswith("resources/"):
                target = root / name
                target.parent.mkdir(parents=True, exist_ok=True)
                target.write_bytes(data)
        modules = traced_modules(root / "resources")
        if linux:
            runtime, keys = runtime_files(root / "resources", modules)
            amended.update({f"resources/{RUNTIME}/{name}": data for name, data in sorted(runtime.items())})
            record.update(keys)
        if win64:
            from .native import windows
            runtime, keys = windows.runtime_files(modules)
            runtime[RUNTIME_DESCRIPTION] = _description(f"{windows.python_version()} (win64, embeddable)",
                                                         modules, keys).encode()
            amended.update({f"resources/{windows.RUNTIME}/{name}": data for name, data in sorted(runtime.items())})
            record.update(keys)
    amended[record_name] = files[record_name] + record_lines(record).encode()
    return amended


def record_lines(record: dict[str, str]) -> str:
    return "".join(f"{key}={value}\n" for key, value in record.items())


def identity() -> bytes:
    """What a standalone FMU's runtime depends on beyond the default build: this module, the trace, numpy's version."""
    import numpy
    here = Path(__file__)
    return (here.read_bytes() + here.with_name("standalone_trace.py").read_bytes()
            + f"numpy {numpy.__version__}".encode())


def describe(fmu: Path) -> dict[str, int]:
    """Size facts of a standalone FMU: the file, and the runtime's share uncompressed and compressed."""
    with zipfile.ZipFile(fmu) as archive:
        runtime = [i for i in archive.infolist() if i.filename.startswith(f"resources/{RUNTIME}/")]
    return {"fmu_bytes": os.path.getsize(fmu), "runtime_files": len(runtime),
            "runtime_bytes": sum(i.file_size for i in runtime), "runtime_compressed": sum(i.compress_size for i in runtime)}
