"""Registry of block kinds: how an FMU's parameters become a block.

A kind is a factory ``factory(params, options) -> Block`` where ``params``
maps each parameter name to its array (full shape) and ``options`` holds the
non-numeric build settings of the definition.  Factories are looked up by
name from a fixed table -- never by evaluating a string.  Inside an FMU this package runs
relocated (:mod:`fmus.runtime.bundled`): the ``kind_module`` a definition records
(``"fmus.runtime.kinds.ltv"``) is imported from the FMU's own code.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable
from typing import Any

import numpy as np

from obsfmu.observers.block import Block
from obsfmu.observers.checks import ParameterError

from ..bundled import local_name, portable_name

Factory = Callable[[dict[str, np.ndarray], dict[str, Any]], Block]

_FACTORIES: dict[str, Factory] = {}
_PACKAGE = portable_name(__name__)  # "fmus.runtime.kinds", relocated or not


def register(name: str) -> Callable[[Factory], Factory]:
    """Decorator: make ``factory`` available under the kind ``name``."""
    def decorate(factory: Factory) -> Factory:
        if name in _FACTORIES:
            raise RuntimeError(f"kind {name!r} registered twice")
        _FACTORIES[name] = factory
        return factory
    return decorate


def create_block(kind: str, params: dict[str, np.ndarray], options: dict[str, Any],
                 module: str | None = None) -> Block:
    """Build the block of ``kind`` (registered by ``module``, imported if needed).

    Only modules of this package can be named; an FMU therefore imports just
    the kind it uses.  Unknown kinds are a :class:`ParameterError`.
    """
    if kind not in _FACTORIES and module:
        if not (module.startswith(_PACKAGE + ".") and module.replace(".", "").replace("_", "").isalnum()):
            raise ParameterError(f"kind_module: {module!r} is not a module of {_PACKAGE}")
        importlib.import_module(local_name(module))
    try:
        factory = _FACTORIES[kind]
    except KeyError:
        raise ParameterError(f"kind: unknown block kind {kind!r}; known: {sorted(_FACTORIES)}") from None
    return factory(params, options)


def load_all() -> None:
    """Import every module of this package; each registers its kinds on import."""
    for module in pkgutil.iter_modules(__path__):
        importlib.import_module(f"{__name__}.{module.name}")


def known_kinds() -> list[str]:
    load_all()
    return sorted(_FACTORIES)


def module_of(kind: str) -> str:
    """The module that registers ``kind``."""
    load_all()
    try:
        return portable_name(_FACTORIES[kind].__module__)
    except KeyError:
        raise ParameterError(f"kind: unknown block kind {kind!r}; known: {sorted(_FACTORIES)}") from None
