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

Default: 2e-3 h (7.2 s), Gauss-Seidel, linear coupling.  As ``Delta`` decays the regression's
conditioning worsens, so coupling errors weigh more later in the run.  The measurements against
the stored reference (``reference.csv``): ``docs/paper004.md``, "Default step and coupling".
"""

from __future__ import annotations

from pathlib import Path

from ...runtime.kinds.signals import source_definition
from ...runtime.kinds.state_affine import chemostat_definition, observer_definition
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
