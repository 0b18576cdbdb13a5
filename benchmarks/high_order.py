"""Plants of order n as design configs (issue 14: observers for plants of order up to 50).

* :func:`chain_config` -- ``x1' = x2, ..., xn' = u``, ``y = x1``: the textbook hard case.  Any
  observer's error matrix is a companion matrix whose gains are the coefficients of the requested
  polynomial (``C(50, 25) p^25`` for a 50-fold pole ``-p``): fast poles cannot be placed or used in
  double precision, and the design refuses them (:mod:`observers.modal`).
* :func:`modes_config` -- a flexible structure: ``n/2`` lightly damped modes ``omega_k``, one
  displacement sensor (the sum of the modal positions), one actuator.  Observer poles: the plant's
  own eigenvalues moved left (``shift``), which the eigenvector placement reaches to 1e-12 at
  n = 50 where Ackermann's controllability matrix has condition 1e30.

Used by ``benchmarks/cosimulation_costs.py`` and ``tests/fmus/test_high_order.py``.
"""

from __future__ import annotations

import numpy as np

from obsfmu.fmus.runtime.kinds.signals import source_definition
from obsfmu.fmus.master import Connection

__all__ = ["chain_config", "modes_config", "input_system"]


def _config(name: str, A, B, C, x0, observer: dict) -> dict:
    return {"name": name, "observer": observer,
            "plant": {"A": np.asarray(A).tolist(), "B": np.asarray(B).tolist(), "C": np.asarray(C).tolist(),
                      "x0": np.asarray(x0, dtype=float).tolist()}}


def chain_config(n: int, observer: dict | None = None, x0=None) -> dict:
    """A parsed config (as :func:`fmus.config.load_config` returns it) of the integrator chain of order n."""
    A = np.diag(np.ones(n - 1), 1)
    B = np.eye(n)[:, -1:]
    C = np.eye(n)[:1]
    start = np.eye(n)[0] if x0 is None else x0
    return _config(f"chain{n}", A, B, C, start, observer or {"t_settle": 2.0, "form": "butterworth"})


def modes_config(n: int, observer: dict | None = None, damping: float = 0.01, omega1: float = 2.0,
                 spacing: float = 2.0) -> dict:
    """``n/2`` modes ``q_k'' + 2 damping omega_k q_k' + omega_k^2 q_k = u``, ``omega_k = omega1 + k spacing``,
    ``y = sum q_k``, ``x = (q_1, q_1', q_2, q_2', ...)``, ``q_k(0) = 1 / (k + 1)``."""
    if n % 2:
        raise ValueError(f"n: a chain of modes has an even order, got {n}")
    modes = n // 2
    A, B, C = np.zeros((n, n)), np.zeros((n, 1)), np.zeros((1, n))
    x0 = np.zeros(n)
    for k in range(modes):
        omega = omega1 + k * spacing
        A[2 * k:2 * k + 2, 2 * k:2 * k + 2] = [[0.0, 1.0], [-omega ** 2, -2.0 * damping * omega]]
        B[2 * k + 1, 0] = 1.0
        C[0, 2 * k] = 1.0
        x0[2 * k] = 1.0 / (k + 1)
    return _config(f"modes{n}", A, B, C, x0, observer or {"shift": 3.0})


def input_system(design, amplitude: float = 0.1, omega: float = 1.0):
    """Definitions, components and connections: ``u = amplitude sin(omega t)`` -> plant -> observer."""
    name = design.name
    source = source_definition(f"{name}_input", sines=1, amplitude=[amplitude], omega=[omega])
    definitions = design.definitions() + [source]
    components = [("source", f"{name}_input", {}), ("plant", f"{name}_plant", {}),
                  ("observer", f"{name}_observer", {})]
    connections = [Connection("source.y", "plant.u"), Connection("source.y", "observer.u"),
                   Connection("plant.y", "observer.y")]
    return definitions, components, connections
