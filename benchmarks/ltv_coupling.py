"""Paper 001's co-simulation error against the monolithic reference vs the settings inside a step.

The table of ``docs/paper001.md``, section 3: for the bounded (20 s) and the paper (15 s)
case, Gauss-Seidel with interpolated inputs, the largest ``|theta_hat - theta_ref|`` on the
stored reference's 0.05 s grid for a communication step ``h``, the degree of the input
polynomials (:class:`observers.ltv.stepping.PolynomialInputs`), the longest RK4 sub-step and the
start-up ramp of the master, with the CPU time of the blocks themselves (the direct loop of
:mod:`benchmarks.direct_loop`, which computes exactly what the FMUs compute).

    .venv/bin/python benchmarks/ltv_coupling.py [--paper]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.direct_loop import DirectLoop                       # noqa: E402
from obsfmu.fmus.scenarios import get                                      # noqa: E402
from obsfmu.fmus.scenarios.ltv_common import load_reference                # noqa: E402

BOUNDED = [  # step, input degree, max_substep, ramp, the observer's f_correction
    (1e-3, 2, 1e-3, 0, 0), (1e-2, 2, 5e-3, 6, 0), (1e-2, 3, 5e-3, 6, 0), (1e-2, 4, 5e-3, 0, 0),
    (1e-2, 4, 5e-3, 6, 0), (1e-2, 4, 1e-2, 6, 0), (1.25e-2, 4, 5e-3, 6, 0), (2.5e-2, 4, 5e-3, 6, 0),
    (1e-2, 4, 5e-3, 6, 1)]
#: the paper case (the scenario's max_dy: 0.1 in the plant, 0.4 in the observer); the old default
#: (1e-4 s, parabolas, no f_correction: 3.0e-5, ~52 s) only with --slow
PAPER = [(1e-3, 2, 1e-3, 6, 0), (1e-3, 2, 1e-3, 6, 1), (1e-3, 3, 1e-3, 0, 1), (1e-3, 3, 1e-3, 6, 1),
         (1e-3, 4, 1e-3, 6, 1), (5e-4, 3, 1e-3, 6, 1), (2e-3, 3, 2e-3, 6, 1), (2e-3, 4, 2e-3, 6, 1)]
SLOW = [(1e-4, 2, 1e-3, 0, 0), (2e-4, 2, 1e-3, 0, 0), (2e-4, 3, 1e-3, 0, 0)]


def deviation(name: str, case: str, step: float, degree: int, substep: float, ramp: int,
              f_correction: int) -> tuple[float, float]:
    scenario = get(name)
    settings = {"input_degree": float(degree), "max_substep": substep}
    observer = {**settings, "f_correction": float(f_correction)}
    components = [(i, m, {**s, **(observer if i == "observer" else settings)} if i in ("plant", "observer") else s)
                  for i, m, s in scenario.components]
    definitions = [d[0] if isinstance(d, tuple) else d for d in scenario.definitions()]
    loop = DirectLoop(definitions, components, scenario.connections)
    start = time.process_time()
    times, rows = loop.run(scenario.stop_time, step, ramp=ramp)
    seconds = time.process_time() - start
    names = [f"{node.name}.{output}" for node in loop.nodes for output in node.output_names]
    theta_hat = rows[:, [names.index(f"observer.theta_hat[{i}]") for i in range(1, 9)]]
    reference = load_reference(case)
    index = np.searchsorted(times, reference["t"] - 1e-9)
    if np.abs(times[index] - reference["t"]).max() > 1e-9:
        raise ValueError(f"step {step:g} misses the reference grid")
    return float(np.abs(theta_hat[index] - reference["theta_hat"]).max()), seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paper", action="store_true", help="also the paper case (about a minute)")
    parser.add_argument("--slow", action="store_true", help="also the paper case at 1e-4 and 2e-4 s (minutes)")
    args = parser.parse_args()
    cases = [("ltv-ls-bounded", "bounded", BOUNDED)] + ([("ltv-ls", "paper", PAPER)] if args.paper else []) \
        + ([("ltv-ls", "paper", SLOW)] if args.slow else [])
    for name, case, rows in cases:
        print(f"\n{name}\n\n| step | input degree | max_substep | ramp | f_correction | max abs theta_hat - ref "
              f"| blocks CPU |")
        print("|---|---|---|---|---|---|---|")
        for row in rows:
            error, seconds = deviation(name, case, *row)
            step, degree, substep, ramp, f_correction = row
            print(f"| {step:g} | {degree} | {substep:g} | {ramp} | {f_correction} | {error:.1e} | {seconds:.1f} s |",
                  flush=True)


if __name__ == "__main__":
    main()
