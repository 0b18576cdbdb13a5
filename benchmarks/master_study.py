"""Error against the monolithic reference vs number of communication steps, per master (issue 9).

For ``ship`` (error of all states against the exact ``expm(Ae t) xe0`` at every communication
point) and ``ltv-ls`` (paper 001's case, error of the 8 parameter estimates against the DOP853
reference at rtol 1e-12 on the stored reference's 0.05 s grid; :mod:`benchmarks.errors`):
Jacobi and Gauss-Seidel with held inputs (plain FMI), Gauss-Seidel with input interpolation
(input derivatives), and the adaptive master.  Prints a Markdown table (used in
docs/interoperability.md) and the wall time of each run.

    .venv/bin/python benchmarks/master_study.py [--quick]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.errors import ERRORS                     # noqa: E402
from obsfmu.fmus.scenarios import ensure_fmus, get, run         # noqa: E402

CONFIGS = [("Jacobi, hold", "jacobi", "hold"), ("Gauss-Seidel, hold", "gauss-seidel", "hold"),
           ("Gauss-Seidel, interpolated", "gauss-seidel", "linear")]


def study(name, error, steps, tolerances, build):
    rows = []
    for label, order, coupling in CONFIGS:
        for step in steps:
            start = time.perf_counter()
            result, _ = run(name, build, step=step, order=order, coupling=coupling)
            wall = time.perf_counter() - start
            rows.append((label, f"h = {step:g}", len(result.time) - 1, error(result), wall))
    for tolerance in tolerances:
        start = time.perf_counter()
        result, _ = run(name, build, order="adaptive", tolerance=tolerance)   # the scenario's step, as `run`
        wall = time.perf_counter() - start
        # every accepted step of length H is recorded as its two halves: communication steps, as `run` prints
        rows.append(("adaptive", f"tol = {tolerance:g}", len(result.time) - 1, error(result), wall))
    print(f"\n### {name}\n\n| master | setting | communication steps | error | wall time |\n|---|---|---|---|---|")
    for label, setting, count, value, wall in rows:
        print(f"| {label} | {setting} | {count} | {value:.2e} | {wall:.1f} s |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="ship only")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as build:
        for scenario in ("ship", "ltv-ls", "ltv-ls-bounded"):
            ensure_fmus(get(scenario), build)
        study("ship", ERRORS["ship"], [1e-2, 1e-3, 1e-4], [1e-4, 1e-5, 1e-6], build)
        if not args.quick:
            # the paper case: one adaptive run takes minutes (tol 1e-4: 183 s) and tolerances below
            # 1e-5 are refused (Scenario.adaptive_floor): the adaptive master is shown on the bounded case
            study("ltv-ls", ERRORS["ltv-ls"], [1e-3, 2e-4, 1e-4], [], build)
            study("ltv-ls-bounded", ERRORS["ltv-ls-bounded"], [1e-2, 1e-3], [1e-3, 1e-4, 1e-6], build)


if __name__ == "__main__":
    main()
