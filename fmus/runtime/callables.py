"""User-supplied Python functions inside FMUs, referenced by name -- never by ``eval``.

Some observers need functions of the user's model (``A(t)``, ``L(t)``,
``f(y)``, a change of coordinates ...).  The user writes them as ordinary
module-level functions in a ``.py`` file; the FMU definition stores only a
reference ``"module:function"`` and the builder bundles the file into the
FMU (``build_fmu(..., extra_modules=[path])``).  At run time
:func:`resolve` imports the module and looks the name up -- the string is
checked against a strict pattern and is never evaluated.  Inside an FMU the bundled modules
run relocated (:mod:`fmus.runtime.bundled`): ``"plants.ltv:f_sin"`` then names the FMU's own copy.
"""

from __future__ import annotations

import importlib
import re
from collections.abc import Callable

from obsfmu.observers.checks import ParameterError

from .bundled import local_name, portable_name

__all__ = ["reference", "resolve"]

_REFERENCE = re.compile(r"^[A-Za-z_]\w*(\.[A-Za-z_]\w*)*:[A-Za-z_]\w*$")


def reference(function: Callable) -> str:
    """``"module:function"`` for a module-level function (the inverse of :func:`resolve`)."""
    module, name = getattr(function, "__module__", None), getattr(function, "__qualname__", "")
    if not module or module == "__main__" or "." in name or "<" in name:
        raise ParameterError(f"{name or function!r}: only module-level functions of an importable module "
                             "can be bundled into an FMU (not lambdas, closures or __main__ functions)")
    return f"{portable_name(module)}:{name}"


def resolve(ref, what: str = "function") -> Callable:
    """Import ``module`` and return its attribute ``function`` for ``ref = "module:function"``; an
    expression function's option (:mod:`fmus.runtime.functions`) is compiled instead."""
    from .functions import compiled, is_expression_function
    if is_expression_function(ref):
        return compiled(ref, what)
    if not isinstance(ref, str) or not _REFERENCE.match(ref):
        raise ParameterError(f"{what}: {ref!r} is not a 'module:function' reference")
    module_name, name = ref.split(":")
    try:
        module = importlib.import_module(local_name(module_name))
    except ImportError as exc:
        raise ParameterError(f"{what}: cannot import module {module_name!r} ({exc}); was it bundled "
                             "with extra_modules when the FMU was built?") from None
    function = getattr(module, name, None)
    if not callable(function):
        raise ParameterError(f"{what}: {module_name!r} has no function {name!r}")
    return function
