"""Wall time of paper 001's co-simulation against the monolithic Radau reference, in one run.

For each case (``bounded``: 20 s, ``paper``: 15 s) and communication step, the three FMUs
(source, plant, observer) are co-simulated with the scenario's defaults otherwise
(Gauss-Seidel, linear coupling) and timed; the independent monolithic solve_ivp solution of
plant + filters + estimator (``fmus/scenarios/ltv_common/reference.py``, Radau, rtol = atol = 1e-10,
information form; for ``bounded`` also the paper's stiff ``F`` form) is timed on the same
horizon.  The scenarios' A(t), L(t), f(y) are expression functions of their system files (before:
the Python functions of plants.ltv; run this file in a checkout of each to compare).  Printed: wall
times, their ratio (co-simulation / Radau), and the largest deviation
of ``theta_hat`` from the reference on a 0.01 s grid -- so speed is never read without accuracy.

The estimator is stiff (``gamma Psi F Psi^T ~ 1e4 1/s`` at t = 0) but the observer integrates it
exactly in information form, so it does not force a small communication step: 1e-3 s is
accurate for the bounded case; the paper case's fast output ``y`` needs the observer's
``f_correction`` at 1e-3 s (its default) and 1e-4 s without it (see docs/paper001.md).  FMUs are
built once (not timed).

    .venv/bin/python benchmarks/ltv_wall_time.py [--cases bounded paper] [--paper-steps 1e-3 1e-4]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from obsfmu.fmus.scenarios import ensure_fmus, get, run
from obsfmu.fmus.scenarios.ltv_common import reference as ref

CASES = {"bounded": ("ltv-ls-bounded", ref.BOUNDED, 20.0), "paper": ("ltv-ls", ref.PAPER, 15.0)}


def timed(function):
    start = time.perf_counter()
    value = function()
    return time.perf_counter() - start, value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+", choices=sorted(CASES), default=["bounded", "paper"])
    parser.add_argument("--bounded-steps", nargs="+", type=float, default=[1e-3])
    parser.add_argument("--paper-steps", nargs="+", type=float, default=[1e-3, 1e-4])
    args = parser.parse_args()

    with tempfile.TemporaryDirectory(prefix="obsfmu_bench_") as build:
        for scenario, _, _ in CASES.values():             # each system file has its own FMUs
            ensure_fmus(get(scenario), Path(build))
        for case in args.cases:
            scenario, unknowns, horizon = CASES[case]
            grid = np.linspace(0.0, horizon, int(round(horizon * 100)) + 1)
            forms = ("information", "F") if case == "bounded" else ("information",)
            radau = {form: timed(lambda: ref.simulate(grid, **unknowns, form=form, method="Radau", rtol=1e-10, atol=1e-10))
                     for form in forms}
            reference = radau["information"][1]
            print(f"\n{case}: {horizon:g} s; monolithic Radau (rtol 1e-10): "
                  + ", ".join(f"{form} form {wall:.2f} s" for form, (wall, _) in radau.items()))
            for step in getattr(args, f"{case}_steps"):
                wall, (result, _) = timed(lambda: run(scenario, build, step=step))
                rows = [result.index_at(t) for t in grid]
                deviation = np.abs(result.vector("observer.theta_hat")[rows] - reference["theta_hat"]).max()
                print(f"  co-simulation, step {step:g} s ({len(result.time) - 1} steps): {wall:.2f} s = "
                      f"{wall / radau['information'][0]:.2f} x Radau; max |theta_hat - reference| = {deviation:.1e}")


if __name__ == "__main__":
    main()
