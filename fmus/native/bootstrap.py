"""Load an FMU's slave class from the code bundled in that FMU (copied to ``resources/obsfmu_bootstrap.py``).

The builder relocates the code an FMU bundles under a package named after the hash of that
code (``resources/_obsfmu_<hash>/``, see :mod:`fmus.bundle`).  The FMU's binary (``bridge.c``)
runs this file with :func:`runpy.run_path` at every instantiation and calls
:func:`load_slave_class`: the package is imported from its own folder -- nothing is added to
``sys.path`` -- so every FMU runs its own code, whatever else the process has imported.

FMUs with the same code hash share the package (their code is identical).  When another
extraction of the same code appears (fmpy deletes its temporary folder after a run), its folder
replaces the vanished ones in the package's ``__path__``, so modules imported lazily later are
still found.
"""

import importlib
import importlib.util
import os
import sys


def load_slave_class(resources: str, package: str, module: str, name: str) -> type:
    """Import ``<package>.<module>`` from ``<resources>/<package>`` and return its class ``name``."""
    directory = os.path.join(resources, package)
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
        bundle.__path__[:] = [d for d in bundle.__path__ if os.path.isdir(d)] + [directory]
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
