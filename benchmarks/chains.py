"""Integrator chains of order n as TOML-style design configs (issue 14: plants of order up to 50).

``x1' = x2, ..., x(n-1)' = xn, xn' = u``, ``y = x1``: the observability matrix is the identity,
so the plant is as well posed as a plant of order n gets, and every difficulty of the observer
design comes from the requested poles.  Used by ``benchmarks/issue14.py`` and the tests.
"""

from __future__ import annotations

import numpy as np

from fmus.kinds.signals import source_definition
from fmus.master import Connection

__all__ = ["chain_config", "chain_system"]


def chain_config(n: int, observer: dict | None = None, x0=None) -> dict:
    """A parsed config (as :func:`fmus.config.load_config` returns it) of the chain of order ``n``."""
    A = np.diag(np.ones(n - 1), 1)
    B = np.zeros((n, 1))
    B[-1, 0] = 1.0
    C = np.zeros((1, n))
    C[0, 0] = 1.0
    start = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float)
    if x0 is None:
        start[0] = 1.0
    return {"name": f"chain{n}",
            "plant": {"A": A.tolist(), "B": B.tolist(), "C": C.tolist(), "x0": start.tolist()},
            "observer": observer or {"t_settle": 2.0, "form": "butterworth"}}


def chain_system(design, amplitude: float = 0.1, omega: float = 1.0):
    """Definitions, components and connections: ``u = amplitude sin(omega t)`` -> plant -> observer."""
    name = design.name
    source = source_definition(f"{name}_input", sines=1, amplitude=[amplitude], omega=[omega])
    definitions = design.definitions() + [source]
    components = [("source", f"{name}_input", {}), ("plant", f"{name}_plant", {}),
                  ("observer", f"{name}_observer", {})]
    connections = [Connection("source.y", "plant.u"), Connection("source.y", "observer.u"),
                   Connection("plant.y", "observer.y")]
    return definitions, components, connections
