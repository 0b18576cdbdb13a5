"""Load an FMU's slave class from the code bundled in that FMU (copied to ``resources/obsfmu_bootstrap.py``).

The builder relocates the code an FMU bundles under a package named after the hash of that
code (``resources/_obsfmu_<hash>/``, see :mod:`fmus.bundle`).  The FMU's binary (``bridge.c``)
runs this file with :func:`runpy.run_path` at every instantiation and calls
:func:`load_slave_class`: the package is imported from its own folder -- nothing is added to
``sys.path`` -- so every FMU runs its own code, whatever else the process has imported.

FMUs with the same code hash share the package (their code is identical).  When another
extraction of the same code appears (fmpy deletes its temporary folder after a run), its folders
join the ``__path__`` of the package and of every subpackage already imported (vanished folders
are dropped), so modules imported lazily later are still found.
"""

import importlib
import importlib.machinery
import importlib.util
import os
import sys

#: the file that marks a standalone FMU's runtime (resources/python/, written by fmus/standalone.py)
RUNTIME_DESCRIPTION = "obsfmu_runtime.txt"


def load_slave_class(resources: str, package: str, module: str, name: str) -> type:
    """Import ``<package>.<module>`` from ``<resources>/<package>`` and return its class ``name``."""
    directory = os.path.join(resources, package)
    _join_runtime(resources)
    bundle = sys.modules.get(package)
    if bundle is None:
        spec = importlib.util.spec_from_file_location(package, os.path.join(directory, "__init__.py"),
                                                      submodule_search_locations=[directory])
        bundle = importlib.util.module_from_spec(spec)
        sys.modules[package] = bundle
        try:
            spec.loader.exec_module(bundle)
        except BaseException:
            del sys.modules[package]
            raise
    elif directory not in bundle.__path__:
        _add_extraction(package, directory)
    try:
        slave = importlib.import_module(f"{package}.{module}")
    except ImportError as exc:
        if exc.name and not exc.name.startswith(package):
            version = ".".join(map(str, sys.version_info[:2]))
            raise ImportError(f"{exc}: this FMU runs on the Python {version} at {sys.executable}, which must have "
                              f"numpy and scipy; install them there, or set OBSFMU_PYTHON to a Python {version} "
                              "installation or virtual environment that has them") from exc
        raise
    return getattr(slave, name)


def _join_runtime(resources: str) -> None:
    """A standalone FMU (fmus/standalone.py) in an interpreter that another standalone FMU's runtime runs:
    this FMU's runtime folders join the module search path after the running one's, and the folders of
    the packages imported from the running runtime (numpy, ...) join their ``__path__`` -- each runtime
    holds only the modules its own FMU imports."""
    if not (sys.flags.isolated and os.path.isfile(os.path.join(sys.prefix, RUNTIME_DESCRIPTION))):
        return  # not a standalone runtime: the host's interpreter, or the one recorded at the build
    record = {}
    own = "win64." if sys.platform == "win32" else ""    # this platform's keys first (obsfmu_native.h)
    with open(os.path.join(resources, "obsfmu_native.txt"), encoding="utf-8") as file:
        for line in file:
            key, _, value = line.rstrip("\n").partition("=")
            if own and key.startswith(own):
                record[key[len(own):]] = value
            else:
                record.setdefault(key, value)
    home = os.path.join(resources, record.get("runtime", ""))
    if not record.get("runtime") or os.path.realpath(home) == os.path.realpath(sys.prefix):
        return
    relative = record["runtime_path"].split(":")
    pairs = [(os.path.join(sys.prefix, r) + os.sep, os.path.join(home, r) + os.sep) for r in relative]
    sys.path.extend(p for p in (os.path.join(home, r) for r in relative) if p not in sys.path)
    _other_runtimes().pairs.extend(pair for pair in pairs if pair not in _other_runtimes().pairs)
    for module in list(sys.modules.values()):
        path = getattr(module, "__path__", None)
        for entry in list(path) if isinstance(path, list) else ():
            for folder in _equivalents(entry, pairs):
                if folder not in path:
                    path.append(folder)


def _equivalents(entry: str, pairs) -> list:
    """The folders of the other runtimes that correspond to ``entry``, a folder of the running one."""
    return [own + entry[len(running):] for running, own in pairs
            if entry.startswith(running) and os.path.isdir(own + entry[len(running):])]


class _OtherRuntimesFinder:
    """The last finder of ``sys.meta_path``: a submodule its package's folders lack (``numpy.ma`` of a package
    imported from a runtime without it) is looked for in the same package's folders of the other standalone FMUs'
    runtimes.  Joining ``__path__`` above covers the packages imported already; this covers those imported
    later -- also by another FMU's thread while this one instantiates (two standalone FMUs started at once: the
    first imported numpy from its runtime, the second then missed ``numpy.ma``)."""

    def __init__(self):
        self.pairs = []      # (a folder of the running runtime, the same folder of another one)

    def find_spec(self, name, path, target=None):
        if not path:
            return None       # a top-level module: sys.path holds every runtime's folders already
        folders = [folder for entry in path for folder in _equivalents(entry, self.pairs)]
        return importlib.machinery.PathFinder.find_spec(name, folders) if folders else None


def _other_runtimes() -> _OtherRuntimesFinder:
    """The process's one finder (this file runs again at each instantiation: the finder is found by its name)."""
    for finder in sys.meta_path:
        if type(finder).__name__ == "_OtherRuntimesFinder":
            return finder
    finder = _OtherRuntimesFinder()
    sys.meta_path.append(finder)
    return finder


def _add_extraction(package: str, directory: str) -> None:
    """Search ``directory`` (another extraction of the same code) in every imported (sub)package."""
    for name, module in list(sys.modules.items()):
        path = getattr(module, "__path__", None)
        if path is None or not (name == package or name.startswith(package + ".")):
            continue
        folder = os.path.join(directory, *name.split(".")[1:])
        if folder not in path:
            path[:] = [d for d in path if os.path.isdir(d)] + [folder]
