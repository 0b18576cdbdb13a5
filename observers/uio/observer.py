r"""Observer of state and sinusoidal disturbance with finite-time DREM (paper 003) as a block.

Plant (1): ``x' = A x + B [theta^T x + f]``, ``y = C x``, ``theta = H xi``,
``xi' = Gamma xi`` (constant for ``Gamma = 0``, the paper's example; otherwise
``theta(t) = H e^{Gamma t} xi(0)`` with a known bounded generator,
:mod:`~observers.uio.generator`), ``f`` a sum of ``N`` sinusoids of unknown
frequencies, amplitudes and phases, relative degree ``r``.  Only ``y`` is
measured.  Four stages run side by side, each on its own finite-time DREM
(:class:`~observers.estimation.FiniteTimeDREM`, eqs. (11)-(12), (18)-(19),
(21)-(22), advanced with the exact exponential update of the scalar laws --
``gamma Delta^2`` reaches 1e10 1/s):

1. ``x_tilde(0)``, the initial error of the unknown-input observer (7)-(8),
   from regression (10) -- exact in finite time (identified once ``nu_1 < mu``);
2. ``xi(0)`` (its free entries) and the annihilator of ``f`` (``omega^2`` for
   ``N = 1``) from regression (17);
3. the amplitudes of ``f_bar`` from (20), then ``f_hat`` by (23);
4. the state ``x_hat``: for ``r = 1`` it is ``z_bar + G_0 y`` (exact after
   stage 1); for ``r >= 2`` an observer of the identified plant with an
   FT-DREM on its initial error (:mod:`~observers.uio.identified_plant`),
   started once stages 2 and 3 are identified.  Before that ``x_hat`` is the
   derivative-free part ``z_bar + G_0 y`` of (8) (``y`` at the last
   communication point).

Regressions (14)-(17), (20) hold only up to decaying filter transients, so
stages 2-4 converge asymptotically; each reports when it is identified
(:mod:`~observers.uio.settling`) and then stops adapting.  See
:mod:`~observers.uio.regressions` for the derivation and the consistent
form of (16)-(17), and ``docs/paper003.md`` for measured numbers.

Every filter of stages 1-2 is one LTI system driven by ``y``
(:class:`~observers.uio.regressions.RegressionSignals`), advanced exactly for
``y`` linear over the step (use interpolated coupling: a held ``y`` lags by
``h/2``).  The DREM laws take their regressors at the start of each step,
held over it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from obsfmu.observers.block import Block, Segment
from obsfmu.observers.checks import ParameterError, as_matrix, as_vector, finite_signal, require_positive
from obsfmu.observers.estimation import FilterBankExtension, FiniteTimeDREM
from obsfmu.observers.integrators import DEFAULT_SUBSTEP_BUDGET, require_budget

from .design import UIODesign
from .generator import GeneratorFlow, check_generator
from .harmonic import harmonic_regressor, undo_filter
from .identified_plant import IdentifiedPlantObserver
from .regressions import RegressionSignals, frequencies_from_annihilator
from .settling import RUNNING, SETTLED, TIMED_OUT, SettlingDetector

__all__ = ["UIOSettings", "UIOFiniteTimeObserver"]


@dataclass
class UIOSettings:
    """Tuning of the observer; the defaults are the paper's example (section "Mathematical modelling").

    Attributes
    ----------
    lambdas : (3,) filter rates ``lambda_1, lambda_2, lambda_3`` of (10), (14), (17) (paper: 10).
    gamma : (4,) FT-DREM gains of stages 1-4 (paper: 1e6).
    mu : FT-DREM switching level in (0, 1) (paper: 0.98).
    rates : extension filter rates ``a_i`` (filters ``a_i/(p + a_i)``) of each stage's DREM,
        ``p_k - 1`` distinct values for ``p_k`` unknowns; ``None``: :func:`default_rates`.
    settle_tol, settle_window, t_identify : identification test of stages 2-4
        (:class:`~observers.uio.settling.SettlingDetector`: tolerance, quiet window, timeout).
    normalize : row-normalise the extended regressions before mixing (default False, the
        paper's ``Delta = det``; normalised, ``gamma Delta^2 <= gamma`` is too slow for stage 2).
    filter_order : order of the filter of (14), ``>= r``; ``None``: ``r + 1``
        (see :class:`~observers.uio.regressions.RegressionSignals`).
    substep_budget : most RK4 sub-steps of stage 4 in one step (a longer step is refused).
    converged_tolerance, decay_rate : the ``converged`` criterion (docs/estimation.md,
        "Diagnostics"): the tolerance, and ``sigma``, a lower bound on the exponential rate of the
        errors of stages 2-4 (``None`` or 0: the slowest filter pole, :meth:`UIOFiniteTimeObserver.slowest_rate`).
    """

    lambdas: tuple = (10.0, 10.0, 10.0)
    gamma: tuple = (1e6, 1e6, 1e6, 1e6)
    mu: float = 0.98
    rates: list | None = None
    settle_tol: float = 1e-6
    settle_window: float = 0.5
    t_identify: float = 10.0
    normalize: bool = False
    filter_order: int | None = None
    substep_budget: int = DEFAULT_SUBSTEP_BUDGET
    converged_tolerance: float = 1e-3
    decay_rate: float | None = None


def default_rates(count: int, lam: float) -> np.ndarray:
    """``count`` distinct extension rates ``lam, lam/2, lam/3, ...`` (``[10, 5]`` for stage 2 of the paper)."""
    return lam / np.arange(1, count + 1)


class UIOFiniteTimeObserver(Block):
    r"""Paper 003's observer of ``x``, ``xi(0)``, ``omega`` and ``f`` from ``y`` alone.

    Parameters
    ----------
    A : (n, n) array_like
    B, C : (n,) array_like
        Single input, single output.
    r : int
        Relative degree; checked: ``C A^k B = 0`` for ``k < r - 1`` and
        ``rank(C A^(r-1) B) = rank B``.
    L : (n,) array_like
        Gain of (2); ``F = M - L C`` must be Hurwitz.
    H : (n, m) array_like
        ``theta = H xi``.
    B_bar : (n,) array_like
        Row with ``B_bar B = 1`` (picks the row of (16)).
    z0 : (n,) array_like
        ``z_r(0)`` of the chain (7) (the paper's ``z_2(0)``).  Not ``x_hat(0)``:
        that would need ``y^(r-1)(0)``.
    xi0_free : (m,) array_like of 0/1
        Entries of ``xi(0)`` to estimate.
    xi0_known : (m,) array_like
        Values of the others (paper: ``theta_1 = 0`` known).
    harmonics : int
        Number ``N`` of sinusoids in ``f`` (Assumption 1).
    settings : UIOSettings, optional
    Gamma : (m, m) array_like, optional
        The known generator ``xi' = Gamma xi`` (absent or zero: constant ``theta``).  ``e^{Gamma t}``
        must be bounded (:func:`~observers.uio.generator.check_generator`); stage 2 then estimates
        ``xi(0)`` and ``theta_hat(t) = H e^{Gamma t} xi0_hat``.

    Ports: input ``y``; outputs ``x_hat`` (n), ``x_tilde0_hat`` (n), ``xi0_hat`` (m),
    ``theta_hat`` (n, at the output's time), ``omega_hat`` (N), ``f_hat`` (1), ``identified`` (4; per stage
    0 running, 1 identified, 2 stopped at the timeout without settling) and
    ``t_identified`` (4; the time, -1 before).
    """

    not_state = ("design", "H", "B_bar", "free", "xi0_known", "harmonics", "lambdas", "gamma", "mu", "normalize",
                 "sizes", "rates", "signals", "_settle", "substep_budget", "converged_tolerance", "decay_rate",
                 "generator")
    state_optional = {"state_stage": "_blank_state_stage", "state_detector": "_blank_state_detector"}

    def __init__(self, A, B, C, r, L, H, B_bar, z0, xi0_free, xi0_known, harmonics=1,
                 settings: UIOSettings | None = None, Gamma=None):
        s = settings or UIOSettings()
        self.design = d = UIODesign.create(A, B, C, r, L)
        n = d.n
        self.H = as_matrix("H", H, shape=(n, None))
        m = self.H.shape[1]
        Gamma = np.zeros((m, m)) if Gamma is None else check_generator(Gamma, m)
        self.generator = GeneratorFlow(Gamma) if np.any(Gamma) else None      # None: the paper's constant theta
        self.B_bar = as_vector("B_bar", B_bar, n)
        if abs(self.B_bar @ d.B - 1.0) > 1e-9:
            raise ParameterError(f"B_bar: B_bar B must be 1, got {self.B_bar @ d.B:.6g}")
        free = as_vector("xi0_free", xi0_free, m)
        if not np.all(np.isin(free, (0.0, 1.0))):
            raise ParameterError(f"xi0_free: entries must be 0 (known) or 1 (estimated), got {free.tolist()}")
        self.free = free.astype(bool)
        self.xi0_known = as_vector("xi0_known", xi0_known, m)
        if float(harmonics) != int(harmonics) or int(harmonics) < 1:
            raise ParameterError(f"harmonics: expected an integer >= 1, got {harmonics!r}")
        self.harmonics = N = int(harmonics)
        self.lambdas = as_vector("lambdas", s.lambdas, 3)
        for i, lam in enumerate(self.lambdas):
            require_positive(f"lambda{i + 1}", lam)
        self.gamma = as_vector("gamma", s.gamma, 4)
        self.mu = float(as_vector("mu", s.mu, 1)[0])
        self.normalize = bool(s.normalize)
        self.substep_budget = require_budget(s.substep_budget)
        m_u = int(self.free.sum())
        self.sizes = (d.V.shape[1], m_u + N + N * m_u, 2 * N, n)           # unknowns of stages 1-4
        rates = s.rates if s.rates is not None else [default_rates(p - 1, self.lambdas[0]) for p in self.sizes]
        if len(rates) != 4:
            raise ParameterError(f"rates: expected the extension rates of 4 stages, got {len(rates)}")
        self.rates = [as_vector(f"rates{k + 1}", rates[k], p - 1) for k, p in enumerate(self.sizes)]
        self.signals = RegressionSignals(d, self.H, self.B_bar, self.free, self.xi0_known, N, self.lambdas,
                                         as_vector("z0", z0, n), s.filter_order, self.generator)
        self.stage = [self._drem(k) for k in range(3)]
        self._settle = (s.settle_tol, s.settle_window, s.t_identify)
        self.converged_tolerance = require_positive("converged_tolerance", s.converged_tolerance)
        rate = 0.0 if s.decay_rate is None else require_positive("decay_rate", s.decay_rate, allow_zero=True)
        self.decay_rate = rate or self.slowest_rate()
        self.detectors = [SettlingDetector(*self._settle) for _ in range(2)]   # stages 2, 3; stage 4 on start
        self.state_stage: IdentifiedPlantObserver | None = None
        self.state_detector: SettlingDetector | None = None
        self.w = self.signals.w0.copy()
        self.y_last = 0.0
        self.input_sizes = {"y": 1}
        self.output_sizes = {"x_hat": n, "x_tilde0_hat": n, "xi0_hat": m, "theta_hat": n, "omega_hat": N,
                             "f_hat": 1, "identified": 4, "t_identified": 4, "excitation": 1, "converged": 1}

    def _drem(self, k: int) -> FiniteTimeDREM:
        return FiniteTimeDREM(FilterBankExtension(self.rates[k]), self.gamma[k], self.mu,
                              normalize=self.normalize)

    # ------------------------------------------------------------------ estimates
    @property
    def x_tilde0(self) -> np.ndarray:
        """Stage 1: ``x_tilde(0)``."""
        return self.design.V @ self.stage[0].theta_hat

    @property
    def xi0(self) -> np.ndarray:
        """Stage 2: ``xi(0)`` (known entries as given)."""
        xi0 = self.xi0_known.copy()
        xi0[self.free] = self.stage[1].theta_hat[:int(self.free.sum())]
        return xi0

    @property
    def theta(self) -> np.ndarray:
        """``H xi0_hat``: ``theta_hat`` for a constant ``theta``, ``theta_hat(0)`` otherwise."""
        return self.H @ self.xi0

    def theta_at(self, t: float) -> np.ndarray:
        """``theta_hat(t) = H e^{Gamma t} xi0_hat`` (``H xi0_hat`` for ``Gamma = 0``)."""
        return self.theta if self.generator is None else self.H @ (self.generator(t) @ self.xi0)

    def _theta_model(self):
        """What stage 4 observes: ``theta_hat`` (constant) or ``s -> theta_hat(s)`` for the current ``xi0_hat``."""
        if self.generator is None:
            return self.theta
        H, flow, xi0 = self.H, self.generator, self.xi0
        return lambda s: H @ (flow(s) @ xi0)

    @property
    def omegas(self) -> np.ndarray:
        """Stage 2: the frequencies, from the annihilator coefficients."""
        m_u = int(self.free.sum())
        return frequencies_from_annihilator(self.stage[1].theta_hat[m_u:m_u + self.harmonics])

    def f_hat(self, t: float) -> float:
        """Stage 3: ``f_hat(t)`` by (23) from the current estimates."""
        return self.disturbance_estimate()(t)

    def disturbance_estimate(self):
        """``t -> f_hat(t)`` for the current estimates (fixed: for a whole step)."""
        omegas = self.omegas
        b = undo_filter(self.stage[2].theta_hat, omegas, self.lambdas[1], self.signals.order)
        return lambda t: float(harmonic_regressor(t, omegas) @ b)

    def x_hat(self) -> np.ndarray:
        """Stage 4 once started, else the derivative-free part ``z_bar + G_0 y`` of (8)."""
        if self.state_stage is not None:
            return self.state_stage.estimate
        return self.signals.z_bar(self.y_last, self.w, self.x_tilde0) + self.design.G_i[0] * self.y_last

    def status(self) -> list[tuple[int, float | None]]:
        """``(status, time)`` of the four stages (status 0 running, 1 identified, 2 timed out)."""
        switch = self.stage[0].switch_time
        stage1 = (RUNNING, None) if switch is None else (SETTLED, switch)
        stages = [stage1] + [(det.status, det.time) for det in self.detectors]
        if self.design.r == 1:
            stages.append(stage1)                     # x_hat = z_bar + G_0 y is exact after stage 1
        elif self.state_detector is None:
            stages.append((RUNNING, None))
        else:
            stages.append((self.state_detector.status, self.state_detector.time))
        return stages

    # ------------------------------------------------------------------ diagnostics contract
    def slowest_rate(self) -> float:
        """The slowest pole of the filters behind stages 2-4: filter and extension rates, ``eig(F)``."""
        rates = [*self.lambdas, *np.concatenate(self.rates), *-np.linalg.eigvals(self.design.F).real]
        if self.generator is not None:                 # the modulated filters lambda I + Gamma^T of (14), (17)
            rates += [lam + self.generator.slowest_decay for lam in self.lambdas[1:]]
        return float(min(rates))

    def _drems(self) -> list[FiniteTimeDREM | None]:
        return self.stage + [None if self.state_stage is None else self.state_stage.drem]

    def excitation(self) -> float:
        """Smallest ``|Delta|`` of the stages adapting now: started (stage 4 starts once stages 2 and 3 are
        identified) and not yet identified; once every stage is identified, of all.  (A stage not yet
        started counted as 0, so the output read 0 while stages 2-3 adapted: issue 36.)"""
        running = [code == RUNNING for code, _ in self.status()]
        drems = self._drems()
        active = [d for d, r in zip(drems, running) if r and d is not None]
        chosen = active or [d for d in drems if d is not None]
        return float(min(abs(d.delta) for d in chosen)) if chosen else 0.0

    def error_bound(self) -> float:
        """Bound on the error of stages 2-4 once all are identified (``inf`` before, or after a timeout).

        If an error decays at least like ``e^{-sigma t}``, a change of at most ``c`` over the quiet
        window ``W`` bounds it by ``c / expm1(sigma W)``; ``c = settle_tol (1 + |reference|)``.
        Stage 1 is exact once its FT-DREM switched (exact regression (10)).
        """
        if any(code != SETTLED for code, _ in self.status()):
            return np.inf
        detectors = self.detectors + ([] if self.state_detector is None else [self.state_detector])
        tol, window = self._settle[0], self._settle[1]
        change = max(tol * (1.0 + float(np.max(np.abs(d.reference)))) for d in detectors)
        return change / np.expm1(self.decay_rate * window) if window > 0 else np.inf

    @property
    def converged(self) -> bool:
        return self.error_bound() <= self.converged_tolerance

    # ------------------------------------------------------------------ Block interface
    def _state_stage(self, theta: np.ndarray, x_hat0: np.ndarray) -> IdentifiedPlantObserver:
        return IdentifiedPlantObserver(self.design.A, self.design.B, self.design.C, theta,
                                       np.linalg.eigvals(self.design.F), x_hat0, self.rates[3], self.gamma[3],
                                       self.mu, self.normalize, self.substep_budget)

    def _blank_state_stage(self) -> IdentifiedPlantObserver:
        """Stage 4 of the right shape to restore a saved state into (see :mod:`observers.state`)."""
        n = self.design.n
        return self._state_stage(np.zeros(n), np.zeros(n))

    def _blank_state_detector(self) -> SettlingDetector:
        return SettlingDetector(*self._settle)

    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        status = self.status()
        return {
            "x_hat": self.x_hat(),
            "x_tilde0_hat": self.x_tilde0.copy(),
            "xi0_hat": self.xi0,
            "theta_hat": self.theta_at(t),
            "omega_hat": self.omegas,
            "f_hat": np.array([self.f_hat(t)]),
            "identified": np.array([float(code) for code, _ in status]),
            "t_identified": np.array([-1.0 if time is None else time for _, time in status]),
            "excitation": np.array([self.excitation()]),
            "converged": np.array([float(self.converged)]),
        }

    def advance(self, t: float, h: float, inputs: Mapping[str, Segment]) -> None:
        """One step; on any failure the state is left as it was (the step rebinds what it changes,
        so the saved state is a cheap rollback point, see :mod:`observers.state`)."""
        segment = inputs["y"]
        y0 = float(finite_signal("input y", segment.start)[0])
        dy = float(finite_signal("input y slope", segment.slope)[0])
        self.atomically(self._step, t, h, y0, dy)

    def _step(self, t: float, h: float, y0: float, dy: float) -> None:
        running = [code == RUNNING for code, _ in self.status()]
        w, x_tilde0, xi0, omegas = self.w, self.x_tilde0.copy(), self.xi0, self.omegas
        if running[0]:
            q1, m1 = self.signals.stage1(y0, w)
            self.stage[0].update(q1, m1, h)                                       # (11)-(12)
        if running[1] or running[2]:
            stage2 = self.signals.stage2(y0, w, x_tilde0, t)
            if running[1]:
                self.stage[1].update(stage2["Y"], stage2["phi"], h)               # (18)-(19)
            if running[2]:
                f_bar = stage2["q"] - stage2["s"] @ xi0                           # (20)
                self.stage[2].update(f_bar, harmonic_regressor(t, omegas), h)     # (21)-(22)
        if self.state_stage is not None:
            self.state_stage.advance(t, h, y0, dy, self._theta_model(), self.disturbance_estimate(),
                                     adapt=running[3])
        self.w = self.signals.advance(w, h, y0, dy)
        self.y_last = y0 + h * dy
        self._watch(t + h)
        if not (np.all(np.isfinite(self.w)) and np.all(np.isfinite(self.x_hat()))):
            raise FloatingPointError(f"observer state not finite at t = {t + h:g}")

    def _watch(self, t: float) -> None:
        """Identification tests at the end of a step; start stage 4 when stages 2-3 are done."""
        stage2, stage3 = self.detectors
        stage2.update(t, self.stage[1].theta_hat, self.stage[1].converged)
        stage3.update(t, self.stage[2].theta_hat, self.stage[2].converged and stage2.done)
        for detector, drem in zip(self.detectors, self.stage[1:]):
            _keep_average_on_timeout(detector, drem)
        if self.design.r == 1:
            return
        if self.state_stage is None:
            if stage2.done and stage3.done:
                self.state_stage = self._state_stage(self.theta_at(t), self.x_hat())
                self.state_detector = SettlingDetector(*self._settle, start=t)
            return
        drem = self.state_stage.drem
        self.state_detector.update(t, drem.theta_hat, drem.converged)
        _keep_average_on_timeout(self.state_detector, drem)


def _keep_average_on_timeout(detector: SettlingDetector, drem: FiniteTimeDREM) -> None:
    """A stage stopped without settling keeps the moving average of its estimate, not the last value.

    With noisy data the high-gain laws follow the noise; the average over the last
    ``settle_window`` seconds is the better value to keep.  (``reset(theta0)`` with ``nu = 1``
    makes the FT-DREM estimate equal ``theta0``; the stage is no longer updated.)
    """
    if detector.status == TIMED_OUT and not detector.average_kept:
        drem.reset(detector.average)
        detector.average_kept = True
