"""Signal sources that drive plants: sine, constant, step, sum of sines, exponential, noise.

One formula covers every waveform the papers use, so a single source FMU is
reused everywhere and switched by parameters (``--set source.offset=5``):

    s(t) = offset + sum_i amplitude_i sin(omega_i t + phase_i)
           + step_height * [t >= step_time] + exp_amplitude * exp(-exp_rate t)
           + noise(t)

``noise`` is zero-mean Gaussian with standard deviation ``noise_std``, held
over intervals of ``noise_dt`` seconds (sample-and-hold), reproducible from
``noise_seed``: the value on interval ``k`` depends only on ``(seed, k)``,
not on the communication step or on how often it is evaluated.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from obsfmu.observers.block import Block, Segment
from obsfmu.observers.checks import ParameterError, as_vector, require_positive
from obsfmu.observers.kernel_forms import ExpressionForm

__all__ = ["SampledNoise", "Waveform", "SignalSource"]


class SampledNoise:
    """Reproducible sample-and-hold Gaussian noise: ``std * N(0, 1)`` on each ``dt`` interval."""

    def __init__(self, std: float, dt: float, seed: int, size: int = 1):
        self.std = require_positive("noise_std", std, allow_zero=True)
        self.dt = require_positive("noise_dt", dt)
        if int(seed) != seed or seed < 0:
            raise ParameterError(f"noise_seed: expected a non-negative integer, got {seed!r}")
        self.seed = int(seed)
        self.size = size

    @staticmethod
    def expression(first: int) -> str:
        """One stream of :meth:`__call__` in the expression language (the compiled kernel's noise), reading ``std``,
        ``dt`` and ``seed`` as ``p[first]``, ``p[first + 1]``, ``p[first + 2]``: the same draws of numpy's stream
        (:mod:`observers.random_stream`), 0 when ``std`` is."""
        std, dt, seed = first, first + 1, first + 2
        interval = f"max(floor(t / p[{dt}] + 1e-09), 0)"
        return f"where(p[{std}] == 0, 0, p[{std}] * randn(p[{seed}], {interval}, 0))"

    def __call__(self, t: float) -> np.ndarray:
        if self.std == 0.0:
            return np.zeros(self.size)
        k = int(np.floor(t / self.dt + 1e-9))
        return self.std * np.random.default_rng((self.seed, max(k, 0))).standard_normal(self.size)


class Waveform:
    """The deterministic part of :class:`SignalSource` as a function of time."""

    def __init__(self, offset=0.0, amplitude=(), omega=(), phase=(), step_time=0.0, step_height=0.0,
                 exp_amplitude=0.0, exp_rate=0.0):
        self.offset = float(as_vector("offset", offset, 1)[0])
        self.amplitude = as_vector("amplitude", amplitude) if np.size(amplitude) else np.zeros(0)
        count = self.amplitude.size
        self.omega = as_vector("omega", omega, count) if count else np.zeros(0)
        self.phase = as_vector("phase", phase, count) if count else np.zeros(0)
        self.step_time = float(as_vector("step_time", step_time, 1)[0])
        self.step_height = float(as_vector("step_height", step_height, 1)[0])
        self.exp_amplitude = float(as_vector("exp_amplitude", exp_amplitude, 1)[0])
        self.exp_rate = float(as_vector("exp_rate", exp_rate, 1)[0])

    def __call__(self, t: float) -> float:
        value = self.offset + float(np.sum(self.amplitude * np.sin(self.omega * t + self.phase)))
        if t >= self.step_time:
            value += self.step_height
        return value + self.exp_amplitude * np.exp(-self.exp_rate * t)

    def parameters(self) -> np.ndarray:
        """The vector ``p`` of :meth:`expression`: offset, amplitudes, omegas, phases, step time and height,
        exponential amplitude and rate."""
        return np.concatenate([[self.offset], self.amplitude, self.omega, self.phase,
                               [self.step_time, self.step_height, self.exp_amplitude, self.exp_rate]])

    @staticmethod
    def expression(sines: int) -> str:
        """:meth:`__call__` of ``sines`` terms in the expression language (:mod:`observers.expressions`), reading
        :meth:`parameters` as ``p``, the same operations in the same order (the compiled kernel's output)."""
        terms = " + ".join(f"p[{2 + i}] * sin(p[{2 + sines + i}] * t + p[{2 + 2 * sines + i}])" for i in range(sines))
        last = 2 + 3 * sines                                   # step_time; then height, exp amplitude, rate
        return (f"p[1] + ({terms or '0'}) + where(t >= p[{last}], p[{last + 1}], 0) "
                f"+ p[{last + 2}] * exp(-p[{last + 3}] * t)")

    def derivative(self, t: float) -> float:
        """Time derivative (the step contributes nothing away from ``step_time``)."""
        value = float(np.sum(self.amplitude * self.omega * np.cos(self.omega * t + self.phase)))
        return value - self.exp_rate * self.exp_amplitude * np.exp(-self.exp_rate * t)


class SignalSource(Block):
    """Block without inputs whose output ``y`` is ``waveform(t) + noise(t)``."""

    stateless = True
    not_state = ("waveform", "noise")

    def __init__(self, waveform: Waveform, noise: SampledNoise | None = None):
        self.waveform = waveform
        self.noise = noise
        self.input_sizes = {}
        self.output_sizes = {"y": 1}

    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        value = np.array([self.waveform(t)])
        if self.noise is not None:
            value = value + self.noise(t)
        return {"y": value}

    def advance(self, t: float, h: float, inputs: Mapping[str, Segment]) -> None:
        """Nothing to integrate: the output is a function of time."""

    @staticmethod
    def expression(sines: int) -> str:
        """:meth:`outputs` in the expression language, reading :meth:`parameters` as ``p``: the waveform
        (:meth:`Waveform.expression`) plus the noise's draw of numpy's stream (:mod:`observers.random_stream`)."""
        return f"{Waveform.expression(sines)} + {SampledNoise.expression(1 + 3 * sines + 4 + 1)}"

    def parameters(self) -> np.ndarray:
        """The waveform's parameters, then the noise's ``std``, ``dt`` and ``seed`` (0, 1, 0 without noise)."""
        noise = (0.0, 1.0, 0.0) if self.noise is None else (self.noise.std, self.noise.dt, self.noise.seed)
        return np.concatenate([self.waveform.parameters(), noise])

    def kernel_form(self) -> ExpressionForm:
        """The compiled kernel's form: :meth:`expression`, compiled when the FMU is built."""
        return ExpressionForm("", 0, (), self.parameters(), (np.inf, 1.0, 1.0, 1.0), outputs=("y",))
