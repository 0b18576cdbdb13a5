"""Seeded noise, sample-and-hold, optionally band-limited, as a source or added to a connection.

:class:`Noise` is a function of time.  Its white sequence holds ``w_k`` on the sample interval
``[k dt, (k + 1) dt)`` (negative times in interval 0):

* ``distribution="gaussian"``: ``w_k = std * N(0, 1)``;
* ``distribution="uniform"``: ``w_k = std * U(-sqrt 3, sqrt 3)`` (the same standard deviation),

drawn from ``numpy.random.default_rng((seed, k))``, so ``w_k`` depends only on ``(seed, k)``, not on
the communication step or on how often or in which order it is evaluated (``size`` streams draw
``size`` values from the same generator: independent streams).  The Gaussian white sequence is
the one of :class:`plants.signals.SampledNoise` with the same ``std``, ``dt`` and ``seed``.

Band-limited (``cutoff_hz`` given): the held white noise drives a low-pass of cut-off
``wc = 2 pi cutoff_hz``, first order ``wc / (s + wc)`` or second-order Butterworth
``wc^2 / (s^2 + sqrt 2 wc s + wc^2)``.  Its input being constant over each interval, the filter is
discretised exactly (zero-order hold): ``x_{k+1} = Ad x_k + Bd w_k``, ``Ad = exp(A dt)``,
``Bd = int_0^dt exp(A s) B ds``, and the output on interval ``k`` is ``z_k = x_k[0]``, the filter
output at ``k dt``, held.  ``x_0`` has the stationary covariance ``P = Ad P Ad' + std^2 Bd Bd'``
(Gaussian, drawn from the generator of interval 0 after its white sample), so the variance of
``z_k`` is ``P[0, 0]`` from the start (first order: ``std^2 (1 - a) / (1 + a)``, ``a = exp(-wc dt)``).

Choice (stateless with a cache): ``z_k`` depends on ``w_0 .. w_{k-1}``, so it is computed by the
recurrence from ``x_0``, term by term in a fixed order (:func:`filter_step`: no BLAS, whose sums may differ from
machine to machine; the compiled step kernel sums the same terms in the same order).  The block keeps the last
state reached and a checkpoint every :data:`CHECKPOINT` intervals; evaluating earlier restarts from the latest
checkpoint before it and runs the same recurrence, so every ``z_k`` is bit-for-bit the same whatever the order of
evaluation.  The cache is not block state (``not_state``).  Cost: ``O(k)`` the first time interval ``k`` is
reached, ``O(1)`` per step when the time goes forward, at most :data:`CHECKPOINT` intervals after a rollback
(more after the compiled kernel went forward: it keeps no checkpoints).
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from obsfmu.observers.block import Block, Segment
from obsfmu.observers.checks import ParameterError, require_positive
from obsfmu.observers.integrators import BudgetError, expm

from obsfmu.observers.kernel_forms import ExpressionForm, PackedForm

from .sources.base import BOUNDARY_TOLERANCE, integer_parameter, interval_index

__all__ = ["CHECKPOINT", "Noise", "NoiseSource", "AddedNoise", "filter_step"]

#: intervals between two saved filter states
CHECKPOINT = 256


def _discrete_low_pass(cutoff_hz: float, order: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``Ad``, ``Bd`` of the low-pass of the module docstring, by one exponential of ``[[A, B], [0, 0]] dt``."""
    wc = 2 * math.pi * cutoff_hz
    if order == 1:
        A, B = np.array([[-wc]]), np.array([[wc]])
    else:
        A, B = np.array([[0.0, 1.0], [-wc ** 2, -math.sqrt(2) * wc]]), np.array([[0.0], [wc ** 2]])
    augmented = np.zeros((order + 1, order + 1))
    augmented[:order, :order], augmented[:order, order:] = A * dt, B * dt
    exponential = expm(augmented)
    return exponential[:order, :order], exponential[:order, order:]


def filter_step(Ad: np.ndarray, Bd: np.ndarray, x: np.ndarray, white: np.ndarray) -> np.ndarray:
    """``x_{k+1} = Ad x_k + Bd w_k`` (``x``: order x streams), each entry summed in a fixed order:
    ``((Ad[i, 0] x[0] + Ad[i, 1] x[1]) + Bd[i] w)`` -- the compiled kernel's order (``fmus/native/kernel_noise.h``)."""
    total = Ad[:, :1] * x[:1]
    for column in range(1, Ad.shape[1]):
        total = total + Ad[:, column:column + 1] * x[column:column + 1]
    return total + Bd * white


def stationary_covariance(Ad: np.ndarray, Bd: np.ndarray, variance: float) -> np.ndarray:
    """``P = Ad P Ad' + variance Bd Bd'`` solved as one linear system in ``vec P``."""
    n = Ad.shape[0]
    Q = variance * (Bd @ Bd.T)
    P = np.linalg.solve(np.eye(n * n) - np.kron(Ad, Ad), Q.reshape(-1)).reshape(n, n)
    return (P + P.T) / 2


class Noise:
    """Seeded sample-and-hold noise of ``size`` streams (see module docstring): ``noise(t)`` -> array.

    Parameters
    ----------
    std : float
        Standard deviation of the white samples ``w_k`` (>= 0; 0 gives zeros).
    sample_interval : float
        ``dt`` (s), > 0: one sample per interval ``[k dt, (k + 1) dt)``, held.
    seed : int
        >= 0; ``w_k`` is drawn from ``default_rng((seed, k))``.
    size : int
        Number of independent streams (the length of ``noise(t)``).
    distribution : {"gaussian", "uniform"}
        Of the white samples, both of standard deviation ``std``.
    cutoff_hz : float, optional
        Cut-off (Hz, > 0) of the low-pass; white noise without it.
    filter_order : {1, 2}
        First order or second-order Butterworth.
    interval_budget : int
        Most filter steps one evaluation may take (band-limited): an evaluation needing more raises
        :class:`~observers.integrators.BudgetError` before any work, so no call takes unbounded time.
    """

    def __init__(self, std: float, sample_interval: float, seed: int, size: int = 1, distribution: str = "gaussian",
                 cutoff_hz: float | None = None, filter_order: int = 1, interval_budget: int = 10 ** 6):
        self.std = require_positive("std", std, allow_zero=True)
        self.dt = require_positive("sample_interval", sample_interval)
        if distribution not in ("gaussian", "uniform"):
            raise ParameterError(f"distribution: expected 'gaussian' or 'uniform', got {distribution!r}")
        self.seed, self.size = integer_parameter("seed", seed, 0), integer_parameter("size", size, 1)
        self.distribution = distribution
        self.interval_budget = integer_parameter("interval_budget", interval_budget, 1)
        self.filter = None
        if cutoff_hz is not None:
            cutoff = require_positive("cutoff_hz", cutoff_hz)
            if filter_order not in (1, 2):
                raise ParameterError(f"filter_order: expected 1 or 2, got {filter_order!r}")
            self.filter = _discrete_low_pass(cutoff, int(filter_order), self.dt)
        self._last: tuple[int, np.ndarray] | None = None
        self._white: tuple[int, np.ndarray] | None = None
        self._checkpoints: dict[int, np.ndarray] = {}

    def _draw(self, rng: np.random.Generator) -> np.ndarray:
        if self.distribution == "gaussian":
            return self.std * rng.standard_normal(self.size)
        return self.std * rng.uniform(-math.sqrt(3.0), math.sqrt(3.0), self.size)

    def white(self, k: int) -> np.ndarray:
        """``w_k``, the held white sample of interval ``k`` (the last one is kept: steps within an interval)."""
        k = int(k)
        if self._white is None or self._white[0] != k:
            self._white = (k, self._draw(np.random.default_rng((self.seed, k))))
        return self._white[1].copy()

    def variance(self) -> float:
        """Variance of the output on any interval: ``std^2`` (white) or ``P[0, 0]`` (band-limited)."""
        if self.filter is None:
            return self.std ** 2
        return float(stationary_covariance(*self.filter, self.std ** 2)[0, 0])

    def _initial_state(self) -> np.ndarray:
        Ad, Bd = self.filter
        rng = np.random.default_rng((self.seed, 0))
        self._draw(rng)                                  # w_0 comes first from this generator
        factor = self.std * np.linalg.cholesky(stationary_covariance(Ad, Bd, 1.0))
        return factor @ rng.standard_normal((Ad.shape[0], self.size))

    def filtered_state(self, k: int) -> np.ndarray:
        """``x_k`` (filter order x size), by the recurrence from the nearest known earlier state."""
        if self._last is None:
            self._last = (0, self._initial_state())
            self._checkpoints[0] = self._last[1]
        reached, x = self._last
        if k < reached:                          # the latest checkpoint before k (a compiled kernel keeps none)
            reached = max(c for c in self._checkpoints if c <= k)
            x = self._checkpoints[reached]
        if k - reached > self.interval_budget:
            raise BudgetError(f"interval_budget: interval {k} needs {k - reached} filter steps from interval "
                              f"{reached}, more than the budget of {self.interval_budget}")
        Ad, Bd = self.filter
        while reached < k:
            x = filter_step(Ad, Bd, x, self.white(reached))
            reached += 1
            if reached % CHECKPOINT == 0:
                self._checkpoints.setdefault(reached, x)
        self._last = (k, x)
        return x.copy()

    def sample(self, k: int) -> np.ndarray:
        """The output on interval ``k``: ``w_k`` or ``z_k``."""
        if self.std == 0.0:
            return np.zeros(self.size)
        return self.white(k) if self.filter is None else self.filtered_state(k)[0].copy()

    def __call__(self, t: float) -> np.ndarray:
        return self.sample(int(interval_index(t, self.dt)))

    def parameters(self) -> np.ndarray:
        """The vector ``p`` that :meth:`expression` reads: ``std``, ``dt``, ``seed`` and the uniform draw's
        ``low = -sqrt 3`` and ``high - low``."""
        return np.array([self.std, self.dt, self.seed, -math.sqrt(3.0), math.sqrt(3.0) - -math.sqrt(3.0)])

    def expression(self, stream: int, index: str | None = None) -> str:
        """Stream ``stream`` of the white sample ``w_k`` in the expression language of ``t`` and ``p`` =
        :meth:`parameters`, the same draws of the same stream (:mod:`observers.random_stream`), the same operations
        in the same order: compiled to C (issue 39), white noise's output.  ``k`` is :func:`interval_index` of
        ``t``, or the expression ``index`` (``"t"``: the compiled filter passes ``k`` as ``t``).  A sample index
        beyond ``2^53`` (``t / dt`` beyond 9e15) is NaN in the expression."""
        k = index or f"clip(floor(t / p[2] + {BOUNDARY_TOLERANCE!r}), 0, {2.0 ** 62!r})"     # interval_index
        draw = f"randn(p[3], {k}, {stream})" if self.distribution == "gaussian" else \
            f"(p[4] + p[5] * rand(p[3], {k}, {stream}))"                             # numpy's uniform(low, high)
        return f"where(p[1] == 0, 0, p[1] * {draw})"

    def filter_form(self, inputs: tuple[str, ...]) -> PackedForm:
        """The compiled kernel's form of band-limited noise (``fmus/native/kernel_noise.h``): the cache's last state
        ``(k, x_k)`` packed, the recurrence :func:`filter_step` in C, ``w_k`` from the kernel library
        (:meth:`expression` of ``k``).  The kernel only goes forward: an earlier interval, or more than
        ``interval_budget`` filter steps, is Python's (its checkpoints, its refusal)."""
        Ad, Bd = self.filter
        order = Ad.shape[0]

        def pack() -> np.ndarray:
            if self._last is None:
                self.filtered_state(0)
            k, x = self._last
            return np.concatenate([[float(k)], x.ravel()])

        def unpack(vector: np.ndarray) -> None:
            self._last = (int(vector[0]), vector[1:].reshape(order, self.size).copy())

        white = self.parameters()
        settings = {"order": order, "streams": self.size, "budget": float(self.interval_budget), "dt": self.dt,
                    "input_u": -1.0, "p_Ad": white.size, "p_Bd": white.size + order * order, "x_longest": 0.0,
                    "x_noted": 0.0, "x_size": 0.0}
        return PackedForm("noise-filter", 1 + order * self.size, inputs, ("y",), settings,
                          np.concatenate([white, Ad.ravel(), Bd.ravel()]), pack, unpack)


class NoiseSource(Block):
    """No inputs; output ``y = noise(t)`` (``size`` streams), held: ``derivative(t) = 0``."""

    stateless = True
    not_state = ("noise",)

    def __init__(self, noise: Noise):
        self.noise = noise
        self.input_sizes = {}
        self.output_sizes = {"y": noise.size}

    def derivative(self, t: float) -> np.ndarray:
        return np.zeros(self.noise.size)

    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {"y": self.noise(t)}

    def advance(self, t: float, h: float, inputs: Mapping[str, Segment]) -> None:
        """Nothing to integrate: the output is a function of time."""

    def kernel_form(self) -> ExpressionForm | PackedForm:
        """The compiled kernel's form: of white noise no state, the outputs :meth:`Noise.expression` (plus ``u``);
        of band-limited noise :meth:`Noise.filter_form`."""
        if self.noise.filter is not None:
            return self.noise.filter_form(tuple(self.input_sizes))
        return ExpressionForm("", 0, tuple(self.input_sizes), self.noise.parameters(), (math.inf, 1.0, 1.0, 1.0),
                              outputs=("y",))


class AddedNoise(NoiseSource):
    """Noise on a connection: input ``u`` (size ``noise.size``), output ``y = u + noise(t)``."""

    feedthrough = True

    def __init__(self, noise: Noise):
        super().__init__(noise)
        self.input_sizes = {"u": noise.size}

    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {"y": np.asarray(inputs["u"], dtype=float) + self.noise(t)}
