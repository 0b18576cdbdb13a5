"""Cost of paper 003's observer: per communication step, through the FMU and called directly.

The observer FMU is driven alone by fmpy (``y`` precomputed from the plant block, set as the
value at the step end with ``y_interpolation = 2``, as the master's Gauss-Seidel coupling does);
the same block is also advanced directly.  Two phases of the 20 s example: while stages 1-4
adapt (0 .. 7.5 s: four FT-DREM updates per step) and after identification (7.6 .. 20 s: the
LTI filters and the stage-4 observer only).  Also the wall time of ``obsfmu run uio-ftdrem``
(plant + observer FMUs and the master).  Best of several repeats, measured in one run.

    .venv/bin/python benchmarks/uio_step_cost.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from obsfmu.fmus.scenarios import ensure_fmus, get, run
from obsfmu.fmus.scenarios.uio_ftdrem import A, B, B_BAR, C, DISTURBANCE, H, R, X0, XI0, XI0_FREE, XI0_KNOWN, Z0, gain
from obsfmu.observers.block import Segment
from obsfmu.observers.uio import UIOFiniteTimeObserver
from obsfmu.plants.uio import DisturbedLTVPlant

STEP, STOP, SPLIT = 1e-3, 20.0, 7.6


def measured_output() -> np.ndarray:
    plant = DisturbedLTVPlant(A, B, C, H, np.zeros((2, 2)), XI0, X0, **DISTURBANCE)
    steps = int(round(STOP / STEP))
    y = np.empty(steps + 1)
    for k in range(steps + 1):
        y[k] = plant.outputs(k * STEP, {})["y"][0]
        if k < steps:
            plant.advance(k * STEP, STEP, {})
    return y


def direct(y: np.ndarray) -> tuple[float, float]:
    """Seconds spent in the two phases, calling the block."""
    observer = UIOFiniteTimeObserver(A, B, C, R, gain(), H, B_BAR, Z0, XI0_FREE, XI0_KNOWN)
    split = int(round(SPLIT / STEP))
    times = []
    for phase in (range(split), range(split, y.size - 1)):
        start = time.perf_counter()
        for k in phase:
            observer.advance(k * STEP, STEP, {"y": Segment.between(y[k:k + 1], y[k + 1:k + 2], STEP)})
            observer.outputs((k + 1) * STEP, {})
        times.append(time.perf_counter() - start)
    return times[0], times[1]


def through_fmu(path, y: np.ndarray) -> tuple[float, float]:
    """Seconds spent in the two phases, in fmi2SetReal + fmi2DoStep + fmi2GetReal of the outputs."""
    description = read_model_description(str(path))
    references = {v.name: v.valueReference for v in description.modelVariables}
    outputs = [v.valueReference for v in description.modelVariables if v.causality == "output"]
    slave = FMU2Slave(guid=description.guid, unzipDirectory=extract(str(path)),
                      modelIdentifier=description.coSimulation.modelIdentifier, instanceName="observer")
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.setInteger([references["y_interpolation"]], [2])
    slave.setReal([references["y"]], [float(y[0])])
    slave.exitInitializationMode()
    split = int(round(SPLIT / STEP))
    times = []
    for phase in (range(split), range(split, y.size - 1)):
        start = time.perf_counter()
        for k in phase:
            slave.setReal([references["y"]], [float(y[k + 1])])
            slave.doStep(k * STEP, STEP)
            slave.getReal(outputs)
        times.append(time.perf_counter() - start)
    final = slave.getReal([references["x_hat[1]"], references["x_hat[2]"]])
    slave.terminate()
    slave.freeInstance()
    return times[0], times[1], final


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    y = measured_output()
    split = int(round(SPLIT / STEP))
    counts = (split, y.size - 1 - split)
    with tempfile.TemporaryDirectory() as build:
        paths = ensure_fmus(get("uio-ftdrem"), build)
        fmu = [through_fmu(paths["uio_ftdrem_observer"], y) for _ in range(args.repeats)]
        scenario = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            run("uio-ftdrem", build)
            scenario.append(time.perf_counter() - start)
    block = [direct(y) for _ in range(args.repeats)]
    print(f"paper 003 observer, step {STEP:g} s, best of {args.repeats}")
    for i, name in enumerate(("identifying (0..7.6 s)", "identified (7.6..20 s)")):
        f = min(run_[i] for run_ in fmu) / counts[i] * 1e6
        d = min(run_[i] for run_ in block) / counts[i] * 1e6
        print(f"  {name:24s} FMU {f:7.1f} us/step   direct {d:7.1f} us/step   FMU/direct {f / d:5.2f}")
    print(f"  scenario uio-ftdrem (20 s, 20000 steps, plant + observer FMUs): {min(scenario):.2f} s wall")
    print(f"  final x_hat through the FMU: {np.round(fmu[-1][2], 6).tolist()}")


if __name__ == "__main__":
    main()
