"""Component types of the signal sources (one per family of :mod:`plants.sources`) and of the noise.

Each type's fields are the arguments of its kind's definition function
(:mod:`fmus.runtime.kinds.sources`, :mod:`fmus.runtime.kinds.noise`), which checks them by building
the signal once; the numeric ones are FMU parameters (``--set``/``--vary`` work on them).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from obsfmu.observers.checks import ParameterError

from ..runtime.kinds import noise, sources
from .schema import Context, Field, register
from .values import MAX_DIMENSION

__all__: list[str] = []

_UNIT = Field("unit", "string", "unit of the signal y", None, example='"V"')
_OFFSET = Field("offset", "number", "constant added", 0.0, "(signal)", "0.5")
_AMPLITUDE = Field("amplitude", "number", "amplitude", 1.0, "(signal)", "0.1")
_PHASE = Field("phase", "number", "phase at the start", 0.0, "rad", "1.57")

_SOURCES = {
    "constant": ("`y(t) = value`", (Field("value", "number", "the constant value", 0.0, "(signal)", "1.0"),)),
    "step": ("`y(t) = offset + height [t >= time]`", (
        Field("time", "number", "time of the step", 0.0, "s", "0.5"),
        Field("height", "number", "height of the step", 1.0, "(signal)", "2.0"), _OFFSET)),
    "ramp": ("`y(t) = offset + slope clip(t - start_time, 0, end_time - start_time)`", (
        Field("start_time", "number", "time the ramp starts", 0.0, "s", "0.1"),
        Field("slope", "number", "rate of the ramp", 1.0, "(signal)/s", "0.5"), _OFFSET,
        Field("end_time", "number", "the output holds from end_time on (absent: never)", None, "s", "2.0"))),
    "sine": ("`y(t) = offset + amplitude sin(2 pi frequency_hz t + phase)`", (
        _AMPLITUDE, Field("frequency_hz", "number", "frequency", 1.0, "Hz", "0.5"), _PHASE, _OFFSET)),
    "multisine": ("`y(t) = offset + sum amplitudes[i] sin(2 pi frequencies_hz[i] t + phases[i])`", (
        Field("amplitudes", "vector", "amplitudes of the sines", unit="(signal)", example="[1, 0.5]"),
        Field("frequencies_hz", "vector", "their frequencies", unit="Hz", example="[0.1, 1.3]"),
        Field("phases", "vector", "their phases at t = 0 (absent: zero)", None, "rad", "[0, 1]"), _OFFSET)),
    "chirp": ("`y(t) = offset + amplitude sin(phi(t))`, a sweep from f0_hz at t0 to f1_hz at t1", (
        _AMPLITUDE, Field("f0_hz", "number", "start frequency", 0.1, "Hz", "0.1"),
        Field("f1_hz", "number", "end frequency", 10.0, "Hz", "5.0"),
        Field("t0", "number", "start of the sweep", 0.0, "s", "0"),
        Field("t1", "number", "end of the sweep", 10.0, "s", "2.0"),
        Field("sweep", "choice", "how the frequency goes from f0_hz to f1_hz", "linear",
              choices=("linear", "exponential")),
        Field("after", "choice", "after t1: hold the end frequency, or stop (y = offset)", "hold",
              choices=("hold", "stop")), _PHASE, _OFFSET)),
    "square": ("`y(t) = offset +- amplitude`, high for the first duty fraction of each period", (
        Field("amplitude", "number", "half the peak-to-peak value", 1.0, "(signal)", "0.2"),
        Field("period", "number", "period", 1.0, "s", "0.5"),
        Field("duty", "number", "fraction of the period at the high level", 0.5, "", "0.25"), _OFFSET)),
    "prbs": ("`y(t) = offset +- amplitude`, the bits of a seeded maximal-length shift register", (
        Field("amplitude", "number", "levels offset +- amplitude", 1.0, "(signal)", "0.1"),
        Field("bit_period", "number", "duration of one bit", 1.0, "s", "0.05"),
        Field("seed", "integer", "initial register, 1 to 2^register_length - 1", 1, "", "5"),
        Field("register_length", "integer", "register length n (2 to 32): period 2^n - 1 bits", 7, "", "9"),
        _OFFSET)),
    "table": ("`y(t)`: interpolation of break points (times[i], values[i])", (
        Field("times", "vector", "break points, strictly increasing", unit="s", example="[0, 1, 2]"),
        Field("values", "vector", "the values there", unit="(signal)", example="[0, 1, 0]"),
        Field("interpolation", "choice", "between break points", "linear", choices=("linear", "previous")))),
    "csv": ("`y(t)`: a column of a CSV file, read when the FMU is built (the FMU holds the numbers)", (
        Field("path", "string", "the CSV file: a regular file of at most 64 MiB, relative to the system file's "
              "folder and inside it (a path leaving it only with outside_folder = true)", example='"input.csv"'),
        Field("outside_folder", "boolean", "allow a path outside the system file's folder (absolute, or with ..)",
              False, example="true"),
        Field("column", "string", "the column's header", example='"u"'),
        Field("time_column", "string", "the header of the time column", "time", example='"t"'),
        Field("interpolation", "choice", "between rows", "linear", choices=("linear", "previous")))),
}


#: the fields that set how fast a source's signal changes (interpolated over a step by linear coupling)
_FREQUENCIES = {"sine": ("frequency_hz",), "multisine": ("frequencies_hz",), "chirp": ("f0_hz", "f1_hz")}


def _source_define(family: str):
    function = getattr(sources, f"{family}_source_definition")

    def define(model_name: str, values: dict, context: Context) -> list:
        arguments = {f.name: values[f.name] for f in TYPES_FIELDS[family]}
        if family == "csv":
            arguments["path"] = _csv_path(context, arguments["path"], arguments.pop("outside_folder"))
        if family == "multisine" and arguments["phases"] is None:
            del arguments["phases"]
        frequencies = [arguments[key] for key in _FREQUENCIES.get(family, ())]
        if frequencies:
            context.rate(2 * np.pi * np.max(np.abs(np.concatenate([np.atleast_1d(f) for f in frequencies]))),
                         f"{' and '.join(_FREQUENCIES[family])} (2 pi f)")
        return [function(model_name, **arguments, description=values["description"])]
    return define


def _csv_path(context: Context, path: str, outside: bool) -> Path:
    """The CSV file of a ``csv`` source, relative to the system file's folder and, unless ``outside``, inside it
    (a system file from someone else names no file of yours: ``/etc/shadow``, ``../../.ssh/id_rsa``)."""
    folder = Path(context.folder).resolve()
    resolved = (folder / path).resolve()
    if not outside and not resolved.is_relative_to(folder):
        raise ParameterError(f"{context.prefix}path: {path!r} is outside the system file's folder {folder}; give "
                             f"outside_folder = true to read it")
    return resolved


TYPES_FIELDS = {family: fields + (_UNIT,) for family, (_, fields) in _SOURCES.items()}
for _family, (_doc, _) in _SOURCES.items():
    register(_family, f"Signal source {_doc}. No inputs; output `y` (one entry).", TYPES_FIELDS[_family],
             _source_define(_family))

_NOISE = (
    Field("size", "integer", "number of streams (entries of y, and of u for added-noise)", 1, example="3",
          maximum=MAX_DIMENSION),
    Field("std", "number", "standard deviation of the white samples", 1.0, "(signal)", "1e-3"),
    Field("sample_interval", "number", "one sample per interval, held", 1e-3, "s", "1e-3"),
    Field("seed", "integer", "seed (>= 0): same seed, same noise, whatever the step", 0, example="7"),
    Field("distribution", "choice", "of the white samples", "gaussian", choices=("gaussian", "uniform")),
    Field("cutoff_hz", "number", "cut-off of a low-pass: band-limited noise (absent: white)", None, "Hz", "20"),
    Field("filter_order", "integer", "order of the low-pass: 1, or 2 (Butterworth)", 1, example="2"),
    Field("interval_budget", "integer", "most filter steps one evaluation may take", 10 ** 6, example="1000000"),
    _UNIT,
)


def _noise_define(function):
    def define(model_name: str, values: dict, context: Context) -> list:
        arguments = {f.name: values[f.name] for f in _NOISE}
        return [function(model_name, **arguments, description=values["description"])]
    return define


register("noise", "Noise source `y = noise(t)`: seeded Gaussian or uniform samples, held, optionally band-limited. "
         "No inputs; output `y` (size entries).", _NOISE, _noise_define(noise.noise_source_definition))
register("added-noise", "Noise on a connection: `y = u + noise(t)` (as `noise`). Input `u`, output `y` (size "
         "entries each).", _NOISE, _noise_define(noise.added_noise_definition))
