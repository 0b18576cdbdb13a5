"""Scenario ``state-affine-chemostat`` -- paper 004, Statement 1: bioreactor with unknown feed concentration.

Three FMUs (time in hours): the dilution rate ``u = D = 0.25 + 0.1 sin(0.5 t) + 0.05 sin(1.3 t)``
(1/h), the chemostat ``X' = mu(S) X - D X``, ``S' = -k mu(S) X + D (S_in - S)`` with Monod
kinetics, measured substrate ``y = S`` (true ``S_in = 10`` g/L, ``x(0) = (2, 3)`` g/L;
:mod:`plants.state_affine`) and the observer of paper 004 for ``chi = x``,
``theta_p = S_in``, time-varying ``Lambda(y, u)`` (Statement 1, ``Phi`` the transition matrix
of ``Lambda``).  Observer: filter rates ``a = (0.2, 1, 5)`` (1/h), ``gamma = gamma_x = 1e7``,
``mu = 0.98``, ``chi_hat(0) = 0``, ``theta_hat(0) = 0``; 0..30 h.

The substrate mode of ``Lambda`` decays (washout at rate ``D``), so ``Delta`` decays too
(interval excitation only): the estimator converges in finite time while ``Delta`` is large,
and the state error then obeys condition (9) through ``Lambda`` itself.

Other plants::

    obsfmu run state-affine-chemostat --set plant.S_in=15 --set plant.x0[1]=1 --set plant.x0[2]=5

Default step and coupling -- measured against the independent monolithic solution
(``fmus/scenarios/state_affine_common/reference.py``, Radau, rtol 1e-10): max deviation over ``t = 0:0.01:30`` h,
final errors (t = 30 h) and the times after which the errors stay below 1e-4 (the reference
itself: 1.63 h and 3.92 h):

=======  ============  ===========  ===========  ============  ============  =============
step, h  order         coupling     dev theta    dev x_hat     final theta   t(1e-4) theta / x, h
=======  ============  ===========  ===========  ============  ============  =============
2e-2     gauss-seidel  linear       2.8e-2       7.0e-4        1.1e-4        never / 20.8
1e-2     gauss-seidel  linear       3.1e-4       1.3e-4        2.7e-5        18.1 / 10.9
5e-3     gauss-seidel  linear       7.7e-5       3.2e-5        6.8e-6        1.63 / 3.93
2e-3     gauss-seidel  linear       1.2e-5       5.1e-6        1.1e-6        1.62 / 3.92
1e-3     gauss-seidel  linear       3.1e-6       1.3e-6        2.7e-7        1.62 / 3.92
2e-3     jacobi        linear       9.8e-5       2.4e-5        5.5e-6        1.62 / 3.92
2e-3     gauss-seidel  hold         4.4e-2       7.2e-3        9.1e-3        never
1e-3     gauss-seidel  hold         2.2e-2       3.6e-3        4.6e-3        never
=======  ============  ===========  ===========  ============  ============  =============

(final ``|x_hat - x|`` at 2e-3 h, Gauss-Seidel, linear: 4.7e-7.)  Second order with linear
coupling, first order (and never within 1e-4) with held inputs.  As ``Delta`` decays the
regression's conditioning worsens, so coupling errors weigh more later in the run: the
default is 2e-3 h (7.2 s), Gauss-Seidel, linear coupling.
"""

from __future__ import annotations

from pathlib import Path

from ...kinds.signals import source_definition
from ...kinds.state_affine import chemostat_definition, observer_definition
from ...master import Connection
from ...result import Result
from .. import Scenario, Summary
from .. import state_affine_common as common

HERE = Path(__file__).parent
REFERENCE = HERE / "reference.csv"

S_IN = 10.0                              #: true feed substrate concentration (g/L)
X0 = [2.0, 3.0]                          #: true initial biomass and substrate (g/L)
RATES = [0.2, 1.0, 5.0]                  #: filter rates a_i (1/h), l + q + p = 3
GAMMA = 1e7                              #: finite-time gradient gain
GAMMA_X = 1e7                            #: gain of the correction term of Statement 3
INPUT = dict(offset=0.25, amplitude=[0.1, 0.05], omega=[0.5, 1.3])
FUNCTIONS = {name: f"plants.state_affine:chemostat_{name}" for name in ("Lambda", "Psi", "w", "phi", "c", "phi_L")}


def definitions():
    return [
        source_definition("state_affine_chemostat_input", sines=2, unit="1/h", **INPUT,
                          description="dilution rate D = offset + sum amplitude[i] sin(omega[i] t), t in hours"),
        chemostat_definition("state_affine_chemostat_plant", S_IN, X0),
        observer_definition(
            "state_affine_chemostat_observer", dims=dict(q=2, p=1, l=0, n=2, ny=1, nu=1), functions=FUNCTIONS,
            rates=RATES, gamma=GAMMA, gamma_x=GAMMA_X, max_substep=0.01,
            units=dict(y="g/L", u="1/h", x=["g/L", "g/L"], theta=["g/L"], time="h"),
            description="paper 004 observer of the chemostat: chi = (X, S), theta_p = S_in, Lambda(y, u)"),
    ]


def summarize(result: Result) -> Summary:
    return common.summarize(result, REFERENCE)


def plot(result: Result, path: Path) -> list[Path]:
    return common.plot(result, path, "paper 004: chemostat with unknown feed concentration, substrate measured",
                ["biomass X", "substrate S"], ["S_in"])


CLAIM = (
        "Paper 004 gives no numerical example; its claims are those of the pendulum scenario "
        "(finite-time parameters, exponential state convergence when Delta is not square integrable). "
        "The plant here is our choice (docs/paper004.md): a chemostat with Monod kinetics, time in "
        "hours, the substrate S measured, the biomass X and the feed concentration S_in = 10 g/L "
        "unknown, dilution rate D = 0.25 + 0.1 sin(0.5 t) + 0.05 sin(1.3 t) 1/h (Statement 1, "
        "time-varying Lambda). Delta decays (washout), so the excitation is only on an interval. The "
        "independent monolithic solution: S_in within 1e-4 from 1.63 h, state from 3.92 h.")

SCENARIO = Scenario(
    name="state-affine-chemostat",
    description="paper 004 (Statement 1): chemostat, unknown biomass and feed concentration, substrate "
                "measured (0..30 h)",
    definitions=definitions,
    components=[("source", "state_affine_chemostat_input", {}), ("plant", "state_affine_chemostat_plant", {}),
                ("observer", "state_affine_chemostat_observer", {})],
    connections=[Connection("source.y", "plant.u"), Connection("source.y", "observer.u"),
                 Connection("plant.y", "observer.y")],
    stop_time=30.0,
    step=2e-3,
    time_unit="h",
    output_interval=1e-2,
    order="gauss-seidel",
    coupling="linear",
    summarize=summarize,
    plot=plot,
    not_adaptive=common.NOT_ADAPTIVE,
    claim=CLAIM,
    measure=common.MEASURE,
)
