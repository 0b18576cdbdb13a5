"""Paper 001's adaptive observer and plant as compiled step kernels' images (issue 39): the state packed into one vector.

The C kernel (``fmus/native/kernel_ltv.h``) takes the same step as :meth:`LTVAdaptiveObserver.advance
<observers.ltv.observer.LTVAdaptiveObserver.advance>` -- polynomial inputs, the sub-steps and ``f_correction``,
RK4 filters with their dense output, the weighted regression at the Gauss nodes, the least-squares information
step -- on the vector :func:`kernel_form` packs, and computes the same outputs.  It needs the model's functions
``A(t)``, ``L(t)``, ``f(y, t)`` compiled to C (expression functions: the build writes them into the FMU's kernel
library; ``C`` constant or ``C(t)`` written as expressions too) and the least-squares estimator before its gain
bound is met; any other observer steps in Python.

The plant (:class:`plants.ltv.OutputNonlinearLTVPlant`, :func:`plant_kernel_form`): ``A(t)``, ``f`` (and ``C(t)``)
compiled to C, no measurement noise (numpy's random stream stays in Python); its packed state is ``x`` and the
samples of ``u`` (:data:`PLANT_SETTINGS`).

The observer's packed state, in order (the offsets are settings of the image, :data:`SETTINGS`)::

    S (n x (1 + (3 + p) n)), Theta_hat (r), P (r x r), lambda_min(P), e^{-beta t},
    the samples of u and of y, the samples of int f(y)      (each [count, times (d + 1), values (d + 1)])
    the memo: [present, t, y, u, A0 (n x n), G (n x (1 + (3 + p) n))]
"""

from __future__ import annotations

import numpy as np

from ..block import MAGNITUDE_BOUND
from ..kernel_forms import PackedForm
from .stepping import PHI_LIMIT, SUBSTEP_POINTS, IntegralSamples, PolynomialInputs, dense_weights

__all__ = ["SETTINGS", "PLANT_SETTINGS", "kernel_form", "plant_kernel_form"]

#: the settings of the image, in the order of the C enum (KT_N .. KT_P_SIZE in fmus/native/kernel_ltv.h); the FMU
#: slave fills input_u, input_y, step_rate, x_longest, x_noted and x_size
SETTINGS = ("n", "p", "r", "degree", "f_correction", "f_time", "c_varies", "max_substep", "max_dy", "budget",
            "gamma", "beta", "f0", "M", "initial_error", "tolerance", "epsilon", "step_rate", "phi_limit",
            "signal_bound", "input_u", "input_y", "x_S", "x_theta", "x_P", "x_lambda", "x_decay", "x_u", "x_y",
            "x_integral", "x_memo", "x_longest", "x_noted", "x_size", "p_f", "p_A", "p_L", "p_C", "p_where",
            "p_known", "p_points", "p_size")
#: the settings of the plant's image, in the order of its C enum (KQ_N .. KQ_P_SIZE); the FMU fills input_u,
#: step_rate, x_longest, x_noted and x_size
PLANT_SETTINGS = ("n", "p", "degree", "f_time", "c_varies", "max_substep", "max_dy", "budget", "signal_bound",
                  "input_u", "step_rate", "x_x", "x_u", "x_longest", "x_noted", "x_size", "p_f", "p_A", "p_C", "p_kbm",
                  "p_theta", "p_noise", "p_size")
#: the outputs the kernel writes, in its order
OUTPUTS = ("x_hat", "theta_hat", "k_hat", "b_hat", "m_hat", "x0_hat", "F_max", "excitation", "converged")
#: the observer's state, all of it packed (``longest_step``: the FMU slave's, when it has a step rate)
_STATE = {"S", "estimator", "inputs", "integral", "_memo_key", "_memo"}


def kernel_form(observer) -> PackedForm | None:
    """The packed form of ``observer`` (an :class:`~observers.ltv.observer.LTVAdaptiveObserver`), or None when it
    steps in Python (module docstring)."""
    estimator = observer.estimator
    constants = [getattr(function, "constants", None) for function in (observer.f, observer.A, observer.L)]
    output = _output_vector(observer.C)
    if not observer.least_squares or output is None or estimator.frozen or any(c is None for c in constants) \
            or set(observer.get_state()) - {"longest_step"} != _STATE or observer.inputs.degree > 5:
        return None
    n, p, r, d = observer.n, observer.p, estimator.p, observer.inputs.degree
    W = 1 + (3 + p) * n
    history = 2 * d + 3
    sizes = {"x_S": n * W, "x_theta": r, "x_P": r * r, "x_lambda": 1, "x_decay": 1, "x_u": history, "x_y": history,
             "x_integral": history, "x_memo": 4 + n * n + n * W}
    offsets, total = _offsets(sizes)
    full = (3 + p) * n
    where = -np.ones(full)
    known = np.zeros(full)
    if observer._columns is None:
        where[:] = np.arange(full)
    else:
        where[observer._columns] = np.arange(r)
        known[observer._known_columns] = observer._known
    points = [*SUBSTEP_POINTS, *(w for point in SUBSTEP_POINTS for w in dense_weights(point))]
    places, parameters = _constants({"p_f": constants[0], "p_A": constants[1], "p_L": constants[2], "p_C": output,
                                     "p_where": where, "p_known": known, "p_points": points})
    settings = dict.fromkeys(SETTINGS, 0.0)
    settings |= {"n": n, "p": p, "r": r, "degree": d, "f_correction": float(observer.f_correction),
                 "f_time": float(observer.f_time), "c_varies": float(observer.C.varies),
                 "max_substep": observer.max_substep, "max_dy": observer.max_dy,
                 "budget": float(observer.substep_budget), "gamma": estimator.gamma, "beta": estimator.beta,
                 "f0": estimator.f0, "M": estimator.M, "initial_error": observer.initial_error,
                 "tolerance": observer.converged_tolerance, "epsilon": observer.regression_error_bound,
                 "phi_limit": PHI_LIMIT, "signal_bound": MAGNITUDE_BOUND, **offsets, **places}
    return PackedForm("ltv-observer", total, ("u", "y"), OUTPUTS, settings, parameters,
                      lambda: _pack(observer, n, W, d), lambda vector: _unpack(observer, vector, offsets, n, W, d))


def plant_kernel_form(plant) -> PackedForm | None:
    """The packed form of paper 001's plant (module docstring), or None when it steps in Python."""
    constants = [getattr(function, "constants", None) for function in (plant.f, plant.A)]
    output = _output_vector(plant.C)
    if output is None or any(c is None for c in constants) or set(plant.get_state()) != {"x", "inputs"} \
            or plant.inputs.degree > 5:
        return None
    n, d = plant.x.size, plant.inputs.degree
    offsets, total = _offsets({"x_x": n, "x_u": 2 * d + 3})
    noise = (0.0, 1.0, 0.0) if plant.noise is None else (plant.noise.std, plant.noise.dt, plant.noise.seed)
    places, parameters = _constants({"p_f": constants[0], "p_A": constants[1], "p_C": output, "p_kbm": plant._kbm,
                                     "p_theta": plant.theta, "p_noise": noise})   # v(t): SampledNoise.expression
    settings = dict.fromkeys(PLANT_SETTINGS, 0.0)
    settings |= {"n": n, "p": plant.nonlinearities.count, "degree": d, "f_time": float(plant.f_time),
                 "c_varies": float(plant.C.varies), "max_substep": plant.max_substep, "max_dy": plant.max_dy,
                 "budget": float(plant.substep_budget), "signal_bound": MAGNITUDE_BOUND, **offsets, **places}

    def pack() -> np.ndarray:
        return np.concatenate([plant.x, _samples(plant.inputs.samples.get("u", (0, (), ())), d)])

    def unpack(vector: np.ndarray) -> None:
        plant.x = vector[:n].copy()
        history = _history(vector[n:], d)
        plant.inputs = PolynomialInputs(d, {"u": history} if history[0] else {})

    return PackedForm("ltv-plant", total, ("u",), ("y", "x", "theta"), settings, parameters, pack, unpack)


def _output_vector(C) -> np.ndarray | None:
    """What the kernel reads of ``C``: the constant vector, or the constants of ``C(t)``'s compiled function; None
    when ``C(t)`` is a Python function (no kernel)."""
    if not C.varies:
        return C.constant
    constants = getattr(C.function, "constants", None)
    return None if constants is None else np.asarray(constants, dtype=float)


def _constants(blocks: dict) -> tuple[dict[str, int], np.ndarray]:
    """The constants the kernel reads as one vector, and where each block of them starts (with ``p_size``)."""
    places, size = _offsets({name: np.size(values) for name, values in blocks.items()})
    return {**places, "p_size": size}, np.concatenate([np.ravel(np.asarray(v, dtype=float)) for v in blocks.values()])


def _offsets(sizes: dict[str, int]) -> tuple[dict[str, int], int]:
    offsets, total = {}, 0
    for name, size in sizes.items():
        offsets[name] = total
        total += size
    return offsets, total


def _samples(samples, d: int) -> list[float]:
    count, times, values = samples
    return [float(count), *times, *values] if count else [0.0] * (2 * d + 3)


def _pack(observer, n: int, W: int, d: int) -> np.ndarray:
    estimator = observer.estimator
    blank = (0, (), ())
    memo = [0.0] * (4 + n * n + n * W) if observer._memo_key is None else \
        [1.0, *observer._memo_key, *np.ravel(observer._memo[0]), *np.ravel(observer._memo[1])]
    return np.concatenate([observer.S.ravel(), estimator.theta_hat, estimator.P.ravel(),
                           [estimator.lambda_min, estimator.decay],
                           _samples(observer.inputs.samples.get("u", blank), d),
                           _samples(observer.inputs.samples.get("y", blank), d),
                           _samples(observer.integral.samples, d), memo])


def _history(vector: np.ndarray, d: int) -> tuple[int, tuple[float, ...], tuple[float, ...]]:
    return int(vector[0]), tuple(vector[1:d + 2].tolist()), tuple(vector[d + 2:2 * d + 3].tolist())


def _unpack(observer, vector: np.ndarray, at: dict[str, int], n: int, W: int, d: int) -> None:
    """The packed state back into the observer: new objects and arrays, rebound (the sharing rule of
    :mod:`observers.state`)."""
    estimator, r = observer.estimator, observer.estimator.p
    observer.S = vector[at["x_S"]:at["x_S"] + n * W].reshape(n, W).copy()
    estimator.theta_hat = vector[at["x_theta"]:at["x_theta"] + r].copy()
    estimator.P = vector[at["x_P"]:at["x_P"] + r * r].reshape(r, r).copy()
    estimator.lambda_min, estimator.decay = float(vector[at["x_lambda"]]), float(vector[at["x_decay"]])
    samples = {name: _history(vector[at[f"x_{name}"]:], d) for name in ("u", "y")}
    observer.inputs = PolynomialInputs(d, {name: value for name, value in samples.items() if value[0]})
    observer.integral = IntegralSamples(d, _history(vector[at["x_integral"]:], d))
    memo = vector[at["x_memo"]:at["x_memo"] + 4 + n * n + n * W]
    if memo[0]:
        observer._memo_key = tuple(memo[1:4].tolist())
        observer._memo = (memo[4:4 + n * n].reshape(n, n).copy(), memo[4 + n * n:].reshape(n, W).copy())
    else:
        observer._memo_key, observer._memo = None, None
