"""observers.checks.unbounded_mode: which linear flows e^(M t) stay bounded, against analytic cases."""

import numpy as np
import pytest

from obsfmu.observers.checks import unbounded_mode


@pytest.mark.parametrize("matrix", [
    [[-1.0, 0.0], [0.0, -2.0]],                 # Hurwitz
    [[0.0, 1.0], [-9.0, 0.0]],                  # a rotation: +-3i, semisimple
    [[0.0, 0.0], [0.0, 0.0]],                   # zero twice, two eigenvectors
    [[-1.0, 1.0], [0.0, -1.0]],                 # a Jordan block off the axis: t e^-t, bounded
    [[0.0, 2.0, 0.0], [-2.0, 0.0, 0.0], [0.0, 0.0, -0.5]],
])
def test_bounded_flows_have_no_unbounded_mode(matrix):
    assert unbounded_mode(np.array(matrix)) is None


@pytest.mark.parametrize("matrix, value, growing, algebraic, geometric", [
    ([[0.5, 0.0], [0.0, -1.0]], 0.5, True, 1, 1),                       # e^(0.5 t)
    ([[0.0, 1.0], [-9.0, 1.0]], 0.5 + 1j * np.sqrt(35) / 2, True, 1, 1),  # lambda^2 - lambda + 9 = 0
    ([[0.0, 1.0], [0.0, 0.0]], 0.0, False, 2, 1),                       # t: a Jordan block at 0
    ([[0.0, 1.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 1.0], [0.0, 0.0, -1.0, 0.0]],
     1j, False, 2, 1),                                                  # t sin t: +-i twice, one eigenvector each
])
def test_growing_and_jordan_modes_are_found(matrix, value, growing, algebraic, geometric):
    mode = unbounded_mode(np.array(matrix))
    assert mode is not None and mode.growing == growing
    assert abs(mode.value.real - np.real(value)) < 1e-6 and abs(abs(mode.value.imag) - abs(np.imag(value))) < 1e-6
    assert (mode.algebraic, mode.geometric) == (algebraic, geometric)
