"""Independent monolithic reference for paper 002 (ship): the composite system of eq. (12).

``xe' = Ae xe`` with ``xe = [x1, x2, x1_hat, x2_hat]``, solved by the matrix exponential.  Written
from the paper's numbers, without importing the project.
"""

import numpy as np
from scipy.linalg import expm

A = np.array([[0.0, 1.0], [-2.0, 3.0]])
B = np.array([[0.0], [1.0]])
C = np.array([[1.0, 0.0]])
K = np.array([[398.0, 43.0]])
N = np.array([[83.0], [1847.0]])
AE = np.block([[A, -B @ K], [N @ C, A - N @ C - B @ K]])
XE0 = np.array([0.05, 0.2, 0.0, 0.0])


def exact(times, xe0=XE0) -> np.ndarray:
    """``xe(t)`` for every ``t`` in ``times`` (rows)."""
    return np.array([expm(AE * t) @ xe0 for t in np.asarray(times, dtype=float)])
