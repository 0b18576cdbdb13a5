"""Per-step cost of the paper-004 observer (issue 8), measured in one run; report ratios, not seconds.

    .venv/bin/python benchmarks/state_affine_step_cost.py [--fmu]

For each example (pendulum: Statement 2, N = 6; chemostat: Statement 1, N = 5) it times, per
communication step at the scenario's default step:

* the observer block's ``advance`` (one internal sub-step) and its parts: one evaluation of the
  user's functions, one evaluation of the filter derivative (RK4 uses four), one mixing
  (``N + 1`` determinants);
* ``advance`` with 4 internal sub-steps;
* the plant block's ``advance``;
* with ``--fmu``: ``fmi2DoStep`` of the observer FMU through fmpy (builds the FMUs into
  ``build/``), i.e. the cost of the FMI layer on top of the block.

Absolute times depend on the machine; the ratios (observer / plant, parts / advance,
FMU / block) are what ``docs/paper004.md`` quotes.
"""

from __future__ import annotations

import sys
import timeit
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from obsfmu.observers.block import Segment  # noqa: E402
from obsfmu.observers.estimation import mix  # noqa: E402
from obsfmu.observers.modal import observer_gain  # noqa: E402
from obsfmu.observers.state_affine import StateAffineModel, StateAffineObserver  # noqa: E402
from obsfmu.plants import state_affine as ex  # noqa: E402


def examples():
    pendulum = StateAffineModel(q=2, p=2, l=0, n=2, ny=1, nu=1, Lambda=ex.PENDULUM_LAMBDA, Psi=ex.pendulum_Psi,
                                w=ex.pendulum_w, phi=ex.pendulum_phi, c=ex.pendulum_c, phi_L=ex.pendulum_phi_L,
                                C=ex.PENDULUM_C, L=observer_gain(ex.PENDULUM_LAMBDA, ex.PENDULUM_C, [2j, -2j]))
    chemostat = StateAffineModel(q=2, p=1, l=0, n=2, ny=1, nu=1, Lambda=ex.chemostat_Lambda, Psi=ex.chemostat_Psi,
                                 w=ex.chemostat_w, phi=ex.chemostat_phi, c=ex.chemostat_c,
                                 phi_L=ex.chemostat_phi_L)
    return [
        ("pendulum", pendulum, [0.5, 2.0, 8.0, 32.0], 1e10, 1e-3, ex.Pendulum(9.81, 0.5, [0.5, 0.0]),
         "state-affine-pendulum", "state_affine_pendulum_observer", (0.3, 1.0)),
        ("chemostat", chemostat, [0.2, 1.0, 5.0], 1e7, 2e-3, ex.Chemostat(10.0, [2.0, 3.0]),
         "state-affine-chemostat", "state_affine_chemostat_observer", (2.0, 0.3)),
    ]


def per_call(function, repeat: int = 5, number: int = 400) -> float:
    """Best of ``repeat`` means over ``number`` calls, seconds per call."""
    return min(timeit.repeat(function, repeat=repeat, number=number)) / number


def fmu_step_cost(scenario: str, model_name: str, h: float, y: float, u: float) -> float:
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    from obsfmu.fmus.scenarios import ensure_fmus, get
    path = ensure_fmus(get(scenario), ROOT / "build")[model_name]
    description = read_model_description(str(path))
    slave = FMU2Slave(guid=description.guid, unzipDirectory=extract(str(path)),
                      modelIdentifier=description.coSimulation.modelIdentifier, instanceName="bench")
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    refs = {v.name: v.valueReference for v in description.modelVariables}
    slave.setReal([refs["y"], refs["u"]], [y, u])
    clock = {"t": 0.0}

    def step():
        slave.doStep(clock["t"], h)
        clock["t"] += h
    cost = per_call(step, repeat=3, number=300)
    slave.terminate()
    slave.freeInstance()
    return cost


def main(with_fmu: bool) -> None:
    print(f"{'example':10s} {'N':>2s} {'advance':>9s} {'4 substeps':>11s} {'plant':>8s} {'obs/plant':>9s} "
          f"{'functions':>9s} {'derivative':>10s} {'mixing':>8s}" + (f" {'FMU step':>9s} {'FMU/block':>9s}"
                                                                      if with_fmu else ""))
    for name, model, rates, gamma, h, plant, scenario, model_name, (y, u) in examples():
        observer = StateAffineObserver(model, rates, gamma, gamma)
        fine = StateAffineObserver(model, rates, gamma, gamma, max_substep=h / 4)
        line = {"y": Segment.between([y], [y * 1.001], h), "u": Segment.between([u], [u * 1.001], h)}
        clock = {"t": 0.0}

        def advance(block=observer):
            block.advance(clock["t"], h, line)
            clock["t"] += h
        block = per_call(advance)
        substeps = per_call(lambda: advance(fine))
        plant_cost = per_call(lambda: plant.advance(0.0, h, {"u": line["u"]}))
        terms = model.evaluate(np.array([y]), np.array([u]))
        P = observer.parametrization
        state = observer.filters
        functions = per_call(lambda: model.evaluate(np.array([y]), np.array([u])), number=2000)
        derivative = per_call(lambda: P.derivative(state, terms, np.array([y])), number=2000)
        mixing = per_call(lambda: mix(*P.regression(state)), number=2000)
        row = (f"{name:10s} {P.N:2d} {block * 1e6:7.0f}us {substeps / block:10.2f}x {plant_cost * 1e6:6.0f}us "
               f"{block / plant_cost:8.1f}x {functions / block:8.0%} {derivative / block:9.0%} {mixing / block:7.0%}")
        if with_fmu:
            fmu = fmu_step_cost(scenario, model_name, h, y, u)
            row += f" {fmu * 1e6:7.0f}us {fmu / block:8.2f}x"
        print(row)
    print("functions/derivative/mixing: one call as a share of one advance (RK4 needs 2 function evaluations "
          "and 4 derivatives per sub-step, plus 1 mixing)")


if __name__ == "__main__":
    main("--fmu" in sys.argv)
