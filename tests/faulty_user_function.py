"""A user's function with a deliberate bug, bundled into the test FMU ``faulty_plant`` (fixture
``faulty_fmus`` of ``tests/conftest.py``).

``f`` is the nonlinearity ``f(y)`` of paper 000's generator plant.  At ``y = 0`` it raises an
exception that is not a numerical fault (``RuntimeError``): what a bug in a user's function looks
like to the FMU.  The step is rolled back, the slave logs it at Error level ("a bug: please report")
and returns -- the one path where the slave logs an error instead of raising -- so by the status
rule the call returns fmi2Error (fmi3Error) and, being a failure and not a refusal, the binary
moves the instance to the FMI error state (FMI 3.0: terminated).  Set ``x0[1] = 0`` before
``ExitInitializationMode`` to trigger it on the first step.
"""

import numpy as np


def f(y):
    if y == 0.0:
        raise RuntimeError("deliberate bug of the test FMU: f(0) is not implemented")
    return np.sin(y)
