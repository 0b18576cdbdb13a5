"""Kinds ``noise-source`` and ``added-noise``: the seeded noise of :mod:`plants.noise` as FMUs.

``noise-source``: no inputs, ``y = noise(t)`` (``size`` streams).  ``added-noise``: noise on a
connection, input ``u`` and output ``y = u + noise(t)`` (direct feedthrough).  The noise depends only
on ``(seed, sample index)``, so a run is reproducible by seed whatever the communication step.
Numeric settings are FMU parameters (``std``, ``sample_interval``, ``seed``, ``cutoff_hz`` when the
noise is band-limited, ``filter_order``, ``interval_budget``); ``distribution`` is an option and
``size`` fixes the ports.
"""

from __future__ import annotations

from obsfmu.observers.expressions import Names
from obsfmu.plants.noise import AddedNoise, Noise, NoiseSource

from ..definition import FmuDefinition, Parameter, Port
from . import register

__all__ = ["noise_source_definition", "added_noise_definition", "kernel_expressions"]


def _noise(p, options) -> Noise:
    cutoff = p.get("cutoff_hz")
    return Noise(float(p["std"]), float(p["sample_interval"]), float(p["seed"]), int(options["size"]),
                 options["distribution"], None if cutoff is None else float(cutoff), float(p["filter_order"]),
                 float(p["interval_budget"]))


@register("noise-source")
def _noise_source(p, options):
    return NoiseSource(_noise(p, options))


@register("added-noise")
def _added_noise(p, options):
    return AddedNoise(_noise(p, options))


def kernel_expressions(definition: FmuDefinition) -> tuple[dict[str, list[str]], Names]:
    """The compiled kernel's expressions and their names: of white noise (no state: ``f`` empty) ``h`` each stream,
    plus ``u`` on a connection; of band-limited noise ``h`` the white samples ``w_k`` of ``k`` passed as ``t``
    (its filter's recurrence is the kernel's, ``fmus/native/kernel_noise.h``)."""
    noise = _noise({p.name: p.array(p.value) for p in definition.parameters}, definition.options)
    if noise.filter is not None:
        return {"f": [], "h": [noise.expression(j, "t") for j in range(noise.size)]}, Names(p=noise.parameters().size)
    added = definition.kind == "added-noise"
    streams = [("u[{}] + " if added else "").format(j + 1) + noise.expression(j) for j in range(noise.size)]
    return {"f": [], "h": streams}, Names(u=noise.size if added else 0, p=noise.parameters().size)


def _definition(model_name: str, kind: str, size: int, std, sample_interval, seed, distribution, cutoff_hz,
                filter_order, interval_budget, unit, description: str, inputs: list[Port]) -> FmuDefinition:
    parameters = [
        Parameter.scalar("std", std, "standard deviation of the white samples", unit),
        Parameter.scalar("sample_interval", sample_interval, "one sample per interval, held", "s"),
        Parameter.scalar("seed", seed, "seed of the noise (an integer >= 0): same seed, same noise"),
    ]
    if cutoff_hz is not None:
        parameters.append(Parameter.scalar("cutoff_hz", cutoff_hz, "cut-off of the low-pass (band limit)", "Hz"))
    parameters += [
        Parameter.scalar("filter_order", filter_order, "order of the low-pass: 1, or 2 (Butterworth)"),
        Parameter.scalar("interval_budget", interval_budget, "most filter steps one evaluation may take"),
    ]
    options = {"size": int(size), "distribution": distribution}
    _noise({p.name: p.array(p.value) for p in parameters}, options)        # a bad setting is refused now
    band = "white" if cutoff_hz is None else "band-limited"
    what = f"{'y = u + ' if inputs else 'y = '}{band} {distribution} noise, seeded, sample-and-hold"
    return FmuDefinition(model_name=model_name, kind=kind, parameters=parameters, inputs=inputs, options=options,
                         feedthrough=bool(inputs), description=description or what,
                         output_derivatives=not inputs,           # held noise: derivative 0 (of u + noise: unknown)
                         outputs=[Port("y", size, what, unit, scalar=size == 1)])


def noise_source_definition(model_name: str, std: float = 1.0, sample_interval: float = 1e-3, seed: int = 0, *,
                            size: int = 1, distribution: str = "gaussian", cutoff_hz: float | None = None,
                            filter_order: int = 1, interval_budget: int = 10 ** 6, unit: str | None = None,
                            description: str = "") -> FmuDefinition:
    """A noise source of ``size`` streams; ``cutoff_hz`` None: white (sample-and-hold)."""
    return _definition(model_name, "noise-source", size, std, sample_interval, seed, distribution, cutoff_hz,
                       filter_order, interval_budget, unit, description, [])


def added_noise_definition(model_name: str, std: float = 1.0, sample_interval: float = 1e-3, seed: int = 0, *,
                           size: int = 1, distribution: str = "gaussian", cutoff_hz: float | None = None,
                           filter_order: int = 1, interval_budget: int = 10 ** 6, unit: str | None = None,
                           description: str = "") -> FmuDefinition:
    """Noise on a connection: ``y = u + noise``, ``u`` and ``y`` of ``size`` entries."""
    u = Port("u", size, "the clean signal", unit, scalar=size == 1)
    return _definition(model_name, "added-noise", size, std, sample_interval, seed, distribution, cutoff_hz,
                       filter_order, interval_budget, unit, description, [u])
