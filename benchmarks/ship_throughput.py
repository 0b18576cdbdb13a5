"""Throughput of the ship scenario (paper 002): through FMUs vs the same blocks called directly.

Both runs use the same algorithm -- Gauss-Seidel order plant -> observer ->
controller, u extrapolated and y interpolated linearly across each step --
so the difference is the cost of FMI (ctypes, pythonfmu's C++ wrapper, the
generic slave).  Prints communication steps per second for both and their
ratio, best of several repeats, measured in one run; also checks that both
give the same trajectory.

    .venv/bin/python benchmarks/ship_throughput.py [--steps 20000] [--repeats 3]
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np

from obsfmu.fmus.scenarios import ensure_fmus, get, run
from obsfmu.observers.block import Segment
from obsfmu.observers.feedback import StateFeedback
from obsfmu.observers.luenberger import LuenbergerObserver
from obsfmu.fmus.scenarios.ship import loop
from obsfmu.plants.lti import LTIPlant


def direct(steps: int, h: float) -> np.ndarray:
    d = loop()                               # the numbers of the scenario's system file
    plant = LTIPlant(*d.plant, x0=d.x0)
    observer = LuenbergerObserver(*d.observer[:3], d.N, d.x_hat0, d.observer[3])
    controller = StateFeedback(d.K)
    r = d.r
    u = controller.outputs(0.0, {"x_hat": observer.x_hat, "r": r})["u"]
    y = plant.outputs(0.0, {"u": u})["y"]
    u_previous = None
    for k in range(steps):
        t = k * h
        u_in = Segment.hold(u) if u_previous is None else Segment(u, (u - u_previous) / h)
        plant.advance(t, h, {"u": u_in})
        y_next = plant.outputs(t + h, {"u": u})["y"]
        observer.advance(t, h, {"u": u_in, "y": Segment.between(y, y_next, h)})
        u_previous, y = u, y_next
        u = controller.outputs(t + h, {"x_hat": observer.x_hat, "r": r})["u"]
    return np.concatenate([plant.x, observer.x_hat])


def best_of(repeats: int, function) -> tuple[float, object]:
    best, value = np.inf, None
    for _ in range(repeats):
        start = time.perf_counter()
        value = function()
        best = min(best, time.perf_counter() - start)
    return best, value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    h = get("ship").step
    with tempfile.TemporaryDirectory() as build:
        ensure_fmus(get("ship"), build)
        fmu_time, result = best_of(args.repeats, lambda: run("ship", build, stop_time=args.steps * h)[0])
    direct_time, final = best_of(args.repeats, lambda: direct(args.steps, h))
    fmu_final = np.concatenate([result.vector("plant.x")[-1], result.vector("observer.x_hat")[-1]])
    print(f"ship scenario, {args.steps} communication steps of {h:g} s, 3 blocks, best of {args.repeats}")
    print(f"  through FMUs (fmpy, native binary):{args.steps / fmu_time:10.0f} steps/s  ({fmu_time:.3f} s, "
          f"includes instantiation)")
    print(f"  Python objects called directly:  {args.steps / direct_time:10.0f} steps/s  ({direct_time:.3f} s)")
    print(f"  ratio direct / FMU:              {fmu_time / direct_time:10.2f}")
    print(f"  max |FMU - direct| final state:  {np.max(np.abs(fmu_final - final)):10.2e}")


if __name__ == "__main__":
    main()
