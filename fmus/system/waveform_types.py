"""Component type ``waveform``: the sum-of-sines source of the paper scenarios (kind ``signal-source``).

``y(t) = offset + sum amplitude[i] sin(omega[i] t + phase[i]) + step_height [t >= step_time]
+ exp_amplitude exp(-exp_rate t)``: the paper scenarios' inputs, in angular frequencies (the
``multisine`` source takes Hz), so that a paper's file writes the numbers of its equations and runs
bit for bit as the scenario always did.  Every coefficient is an FMU parameter.
"""

from __future__ import annotations

import numpy as np

from obsfmu.observers.checks import ParameterError

from ..runtime.kinds.signals import source_definition
from .schema import Context, Field, register

__all__: list[str] = []

_FIELDS = (
    Field("offset", "number", "constant term", 0.0, "(signal)", "0.25"),
    Field("amplitude", "vector", "sine amplitudes", unit="(signal)", example="[3, 4]"),
    Field("omega", "vector", "their angular frequencies (as many as amplitudes)", unit="rad/(time unit)",
          example="[1.3, 4.7]"),
    Field("phase", "vector", "their phases at t = 0 (absent: zero)", None, "rad", "[0, 1.57]"),
    Field("step_time", "number", "time of the step", 0.0, "(time unit)", "5"),
    Field("step_height", "number", "height of the step", 0.0, "(signal)", "1"),
    Field("exp_amplitude", "number", "amplitude of exp_amplitude exp(-exp_rate t)", 0.0, "(signal)", "0.5"),
    Field("exp_rate", "number", "decay rate of the exponential", 0.0, "1/(time unit)", "2"),
    Field("unit", "string", "unit of the signal y", None, example='"rad/s2"'),
)


def _define(model_name: str, values: dict, context: Context) -> list:
    sines = np.size(values["amplitude"])
    for key in ("omega", "phase"):
        if values[key] is not None and np.size(values[key]) != sines:
            raise ParameterError(f"{key}: expected {sines} entries (one per amplitude), got {np.size(values[key])}")
    arguments = {f.name: values[f.name] for f in _FIELDS}
    return [source_definition(model_name, sines, **arguments, description=values["description"])]


register("waveform", "Signal source `y(t) = offset + sum amplitude[i] sin(omega[i] t + phase[i]) + step_height "
         "[t >= step_time] + exp_amplitude exp(-exp_rate t)` (angular frequencies; `multisine` takes Hz). No inputs; "
         "output `y` (one entry).", _FIELDS, _define)
