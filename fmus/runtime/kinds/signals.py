"""Kind ``signal-source``: the waveform/noise source of :mod:`plants.signals` as an FMU."""

from __future__ import annotations

import numpy as np

from obsfmu.observers.expressions import Names
from obsfmu.plants.signals import SampledNoise, SignalSource, Waveform

from ..definition import FmuDefinition, Parameter, Port
from . import register

__all__ = ["source_definition", "kernel_expressions"]


@register("signal-source")
def _signal_source(p, options):
    waveform = Waveform(p["offset"], p["amplitude"], p["omega"], p["phase"], p["step_time"],
                        p["step_height"], p["exp_amplitude"], p["exp_rate"])
    noise = None
    if float(p["noise_std"]) != 0.0:
        noise = SampledNoise(float(p["noise_std"]), float(p["noise_dt"]), float(p["noise_seed"]))
    return SignalSource(waveform, noise)


def kernel_expressions(definition: FmuDefinition) -> tuple[dict[str, list[str]], Names]:
    """The compiled kernel's expressions (no state: ``f`` empty, ``h`` the waveform and its noise) and their
    names."""
    sines = next(len(p.value) for p in definition.parameters if p.name == "amplitude")
    return {"f": [], "h": [SignalSource.expression(sines)]}, Names(p=1 + 3 * sines + 4 + 3)


def source_definition(model_name: str, sines: int = 2, *, offset=0.0, amplitude=None, omega=None,
                      phase=None, step_time=0.0, step_height=0.0, exp_amplitude=0.0, exp_rate=0.0,
                      noise_std=0.0, noise_dt=1e-3, noise_seed=0, unit: str | None = None,
                      description: str = "") -> FmuDefinition:
    """A source with ``sines`` sine terms; every coefficient is a parameter (default 0)."""
    zeros = np.zeros(sines)
    return FmuDefinition(
        model_name=model_name,
        kind="signal-source",
        description=description or ("y(t) = offset + sum amplitude[i] sin(omega[i] t + phase[i]) "
                                     "+ step_height [t >= step_time] + exp_amplitude exp(-exp_rate t) + noise"),
        parameters=[
            Parameter.scalar("offset", offset, "constant term", unit),
            Parameter.of("amplitude", zeros if amplitude is None else amplitude, "sine amplitudes", unit),
            Parameter.of("omega", zeros if omega is None else omega, "sine angular frequencies", "rad/s"),
            Parameter.of("phase", zeros if phase is None else phase, "sine phases", "rad"),
            Parameter.scalar("step_time", step_time, "time of the step", "s"),
            Parameter.scalar("step_height", step_height, "height of the step", unit),
            Parameter.scalar("exp_amplitude", exp_amplitude, "amplitude of exp_amplitude exp(-exp_rate t)", unit),
            Parameter.scalar("exp_rate", exp_rate, "decay rate of the exponential", "1/s"),
            Parameter.scalar("noise_std", noise_std, "standard deviation of the sample-and-hold Gaussian noise", unit),
            Parameter.scalar("noise_dt", noise_dt, "hold interval of the noise", "s"),
            Parameter.scalar("noise_seed", noise_seed, "seed of the noise (a non-negative integer)"),
        ],
        inputs=[],
        outputs=[Port("y", 1, "source signal", unit, scalar=True)],
    )
