"""Kinds ``<family>-source``: the deterministic signal sources of :mod:`plants.sources` as FMUs.

One kind per family (constant, step, ramp, sine, multisine, chirp, square, prbs, table); a CSV column
is a table whose break points are read from the file when the FMU is BUILT (:func:`csv_source_definition`),
so the FMU never depends on a file on the target.  Every numeric setting is an FMU parameter named as
the source's argument (``--set``/``--vary`` work on it); the strings (chirp ``sweep``/``after``, table
``interpolation``) are definition options.  Each definition function builds the source once, so a bad
setting is refused at build time, naming it.  No inputs; one output ``y`` with the signal's unit.

The sources know their exact derivative (:meth:`plants.sources.Source.derivative`, one-sided from the
right at a jump): the FMUs export it (``maxOutputDerivativeOrder = 1``, ``fmi2GetRealOutputDerivatives``),
so a master can hand it to a consumer as its input derivative (``fmi2SetRealInputDerivatives``) and
linear coupling of a smooth source is exact.  (The project's master does not read output
derivatives; it interpolates between a producer's outputs at ``t`` and ``t + h`` -- Gauss-Seidel.)
"""

from __future__ import annotations

import numpy as np

from obsfmu.observers.expressions import Names
from obsfmu.plants.sources import PRBS, Chirp, Constant, CsvColumn, MultiSine, Ramp, Sine, Square, Step, Table
from obsfmu.plants.sources.base import c_value_source

from ..definition import FmuDefinition, Parameter, Port
from . import register

__all__ = ["SOURCE_KINDS", "kernel_expressions", "constant_source_definition", "step_source_definition", "ramp_source_definition",
           "sine_source_definition", "multisine_source_definition", "chirp_source_definition",
           "square_source_definition", "prbs_source_definition", "table_source_definition",
           "csv_source_definition"]

#: family -> the source class; the kind is ``<family>-source``
SOURCE_KINDS = {"constant": Constant, "step": Step, "ramp": Ramp, "sine": Sine, "multisine": MultiSine,
                "chirp": Chirp, "square": Square, "prbs": PRBS, "table": Table}


def _arguments(p: dict[str, np.ndarray], options: dict) -> dict:
    """The source's keyword arguments: the parameters (scalars as floats) and the options."""
    return {**{name: float(value) if value.ndim == 0 else value for name, value in p.items()}, **options}


def _factory(source_class):
    return lambda p, options: source_class(**_arguments(p, options))


for _family, _class in SOURCE_KINDS.items():
    register(f"{_family}-source")(_factory(_class))


def _built(definition: FmuDefinition):
    family = definition.kind.removesuffix("-source")
    return SOURCE_KINDS[family](**_arguments({p.name: p.array(p.value) for p in definition.parameters},
                                             definition.options))


def kernel_expressions(definition: FmuDefinition):
    """The compiled kernel's expressions of a source whose output has one (``f`` empty, ``h`` its value) and their
    names; None for the others (prbs, table: :func:`kernel_c_source`)."""
    source = _built(definition)
    text = source.expression()
    return None if text is None else ({"f": [], "h": [text]}, Names(p=source.parameters().size))


def kernel_c_source(definition: FmuDefinition) -> str | None:
    """The kernel library of a source whose value is C of its own (prbs, table: :meth:`Source.c_value`)."""
    value = _built(definition).c_value()
    return None if value is None else c_value_source(value)


def _per_second(unit):
    return f"{unit}/s" if unit else None


def _source(model_name: str, family: str, description: str, unit, parameters: list[Parameter],
            options: dict | None = None) -> FmuDefinition:
    """The definition of a ``family`` source, its settings checked by building it once."""
    options = options or {}
    SOURCE_KINDS[family](**_arguments({p.name: p.array(p.value) for p in parameters}, options))
    return FmuDefinition(model_name=model_name, kind=f"{family}-source", description=description,
                         parameters=parameters, inputs=[], options=options, output_derivatives=True,
                         outputs=[Port("y", 1, f"{family} signal", unit, scalar=True)])


def _scalars(unit, **settings: tuple[float, str, str | None]) -> list[Parameter]:
    """Scalar parameters ``name=(value, description, unit)``; the unit ``"="`` is the signal's."""
    return [Parameter.scalar(name, value, text, unit if own == "=" else own)
            for name, (value, text, own) in settings.items()]


def constant_source_definition(model_name: str, value: float = 0.0, *, unit: str | None = None,
                               description: str = "") -> FmuDefinition:
    return _source(model_name, "constant", description or "y(t) = value", unit,
                   _scalars(unit, value=(value, "the constant value", "=")))


def step_source_definition(model_name: str, time: float = 0.0, height: float = 1.0, offset: float = 0.0, *,
                           unit: str | None = None, description: str = "") -> FmuDefinition:
    return _source(model_name, "step", description or "y(t) = offset + height [t >= time]", unit,
                   _scalars(unit, time=(time, "time of the step", "s"), height=(height, "height of the step", "="),
                            offset=(offset, "value before the step", "=")))


def ramp_source_definition(model_name: str, start_time: float = 0.0, slope: float = 1.0, offset: float = 0.0,
                           end_time: float | None = None, *, unit: str | None = None,
                           description: str = "") -> FmuDefinition:
    """A ramp; ``end_time`` None: it never saturates (and has no ``end_time`` parameter)."""
    parameters = _scalars(unit, start_time=(start_time, "time the ramp starts", "s"),
                          slope=(slope, "rate of the ramp", _per_second(unit)),
                          offset=(offset, "value before start_time", "="))
    if end_time is not None:
        parameters += _scalars(unit, end_time=(end_time, "the output holds from end_time on", "s"))
    return _source(model_name, "ramp", description or "y(t) = offset + slope clip(t - start_time, 0, "
                   "end_time - start_time)", unit, parameters)


def sine_source_definition(model_name: str, amplitude: float = 1.0, frequency_hz: float = 1.0, phase: float = 0.0,
                           offset: float = 0.0, *, unit: str | None = None, description: str = "") -> FmuDefinition:
    return _source(model_name, "sine", description or "y(t) = offset + amplitude sin(2 pi frequency_hz t + phase)",
                   unit, _scalars(unit, amplitude=(amplitude, "amplitude", "="),
                                  frequency_hz=(frequency_hz, "frequency", "Hz"), phase=(phase, "phase at t = 0", "rad"),
                                  offset=(offset, "constant added", "=")))


def multisine_source_definition(model_name: str, amplitudes, frequencies_hz, phases=None, offset: float = 0.0, *,
                                unit: str | None = None, description: str = "") -> FmuDefinition:
    amplitudes = np.atleast_1d(np.asarray(amplitudes, dtype=float))
    phases = np.zeros(amplitudes.size) if phases is None else phases
    return _source(model_name, "multisine", description or "y(t) = offset + sum amplitudes[i] "
                   "sin(2 pi frequencies_hz[i] t + phases[i])", unit, [
                       Parameter.of("amplitudes", amplitudes, "amplitudes of the sines", unit),
                       Parameter.of("frequencies_hz", np.atleast_1d(frequencies_hz), "their frequencies", "Hz"),
                       Parameter.of("phases", np.atleast_1d(phases), "their phases at t = 0", "rad"),
                       Parameter.scalar("offset", offset, "constant added", unit)])


def chirp_source_definition(model_name: str, amplitude: float = 1.0, f0_hz: float = 0.1, f1_hz: float = 10.0,
                            t0: float = 0.0, t1: float = 10.0, sweep: str = "linear", after: str = "hold",
                            phase: float = 0.0, offset: float = 0.0, *, unit: str | None = None,
                            description: str = "") -> FmuDefinition:
    """A sweep from ``f0_hz`` to ``f1_hz`` over ``[t0, t1]``; ``sweep`` and ``after`` are options."""
    return _source(model_name, "chirp", description or f"y(t) = offset + amplitude sin(phi(t)), {sweep} sweep "
                   f"from f0_hz at t0 to f1_hz at t1, then {after}", unit,
                   _scalars(unit, amplitude=(amplitude, "amplitude", "="), f0_hz=(f0_hz, "start frequency", "Hz"),
                            f1_hz=(f1_hz, "end frequency", "Hz"), t0=(t0, "start of the sweep", "s"),
                            t1=(t1, "end of the sweep", "s"), phase=(phase, "phase at t0", "rad"),
                            offset=(offset, "constant added", "=")),
                   {"sweep": sweep, "after": after})


def square_source_definition(model_name: str, amplitude: float = 1.0, period: float = 1.0, duty: float = 0.5,
                             offset: float = 0.0, *, unit: str | None = None, description: str = "") -> FmuDefinition:
    return _source(model_name, "square", description or "y(t) = offset + amplitude for the first duty fraction "
                   "of each period, offset - amplitude for the rest", unit,
                   _scalars(unit, amplitude=(amplitude, "half the peak-to-peak value", "="),
                            period=(period, "period", "s"), duty=(duty, "fraction of the period at the high level", None),
                            offset=(offset, "mean level", "=")))


def prbs_source_definition(model_name: str, amplitude: float = 1.0, bit_period: float = 1.0, seed: int = 1,
                           register_length: int = 7, offset: float = 0.0, *, unit: str | None = None,
                           description: str = "") -> FmuDefinition:
    return _source(model_name, "prbs", description or "y(t) = offset +- amplitude, the bits of a seeded "
                   "maximal-length shift register, one per bit_period", unit,
                   _scalars(unit, amplitude=(amplitude, "levels offset +- amplitude", "="),
                            bit_period=(bit_period, "duration of one bit", "s"),
                            seed=(seed, "initial register, 1 to 2^register_length - 1", None),
                            register_length=(register_length, "register length n (2 to 32): period 2^n - 1 bits", None),
                            offset=(offset, "mean level", "=")))


def table_source_definition(model_name: str, times, values, interpolation: str = "linear", *,
                            unit: str | None = None, description: str = "") -> FmuDefinition:
    """A table of break points ``(times[i], values[i])``; ``interpolation`` ("linear", "previous") is an option."""
    times = np.atleast_1d(np.asarray(times, dtype=float))
    return _source(model_name, "table", description or f"y(t): {interpolation} interpolation of "
                   f"{times.size} break points", unit,
                   [Parameter.of("times", times, "break points, strictly increasing", "s"),
                    Parameter.of("values", np.atleast_1d(values), "the values there", unit)],
                   {"interpolation": interpolation})


def csv_source_definition(model_name: str, path, column: str, time_column: str = "time",
                          interpolation: str = "linear", *, unit: str | None = None,
                          description: str = "") -> FmuDefinition:
    """A column of a CSV file, read NOW into a table (the FMU holds the numbers, not the file)."""
    data = CsvColumn(path, column, time_column, interpolation)
    return table_source_definition(model_name, data.times, data.values, interpolation, unit=unit,
                                   description=description or f"y(t): column {column!r} of {path} "
                                                              f"({interpolation} interpolation)")
