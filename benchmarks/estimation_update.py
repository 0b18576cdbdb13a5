"""Micro-benchmark: cost of one ``update`` of each estimator of observers.estimation.

This is the floor an observer FMU pays per communication step for its
parameter estimator.  For p = 2, 4, 8, 10 each estimator is warmed up on
random samples, then ``update`` is timed with :mod:`timeit` (several repeats,
the minimum is reported, in microseconds per update).

Run:  .venv/bin/python benchmarks/estimation_update.py [--number N] [--repeat R]
"""

from __future__ import annotations

import argparse
import platform
import timeit

import numpy as np

from obsfmu.observers.estimation import (
    DREM,
    DelayExtension,
    DiscreteDREM,
    FilterBankExtension,
    FiniteTimeDREM,
    Gradient,
    KreisselmeierExtension,
    LeastSquaresForgetting,
)

SIZES = (2, 4, 8, 10)
DT = 1e-3

ESTIMATORS = {
    "Gradient": lambda p: Gradient(p, 1.0),
    "LeastSquaresForgetting": lambda p: LeastSquaresForgetting(p, 1000.0, 1.0, 0.1, 1e12),
    "DREM (filter bank)": lambda p: DREM(FilterBankExtension(np.arange(1.0, p)), 10.0),
    "DREM (Kreisselmeier)": lambda p: DREM(KreisselmeierExtension(p, 1.0), 10.0),
    "DREM (delays)": lambda p: DREM(DelayExtension(range(1, p)), 10.0),
    "FiniteTimeDREM (filter bank)": lambda p: FiniteTimeDREM(FilterBankExtension(np.arange(1.0, p)), 10.0, 0.98),
    "DiscreteDREM (delays)": lambda p: DiscreteDREM(DelayExtension(range(1, p)), 1e-4),
}


def microseconds_per_update(make, p: int, number: int, repeat: int) -> float:
    rng = np.random.default_rng(p)
    theta = rng.uniform(-1.0, 1.0, p)
    estimator = make(p)
    dt = 1 if isinstance(estimator, DiscreteDREM) else DT
    for _ in range(2 * p + 5):                       # fill delay lines and filters
        phi = rng.uniform(-1.0, 1.0, p)
        estimator.update(phi @ theta, phi, dt)
    phi = rng.uniform(-1.0, 1.0, p)
    y = float(phi @ theta)
    times = timeit.repeat(lambda: estimator.update(y, phi, dt), number=number, repeat=repeat)
    return min(times) / number * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--number", type=int, default=1000, help="updates per timing (default 1000)")
    parser.add_argument("--repeat", type=int, default=7, help="timings, the minimum is reported (default 7)")
    args = parser.parse_args()
    print(f"Python {platform.python_version()}, NumPy {np.__version__}, {platform.machine()}; "
          f"min of {args.repeat} x {args.number} updates, microseconds per update\n")
    header = "| estimator | " + " | ".join(f"p = {p}" for p in SIZES) + " |"
    print(header)
    print("|" + "---|" * (len(SIZES) + 1))
    for name, make in ESTIMATORS.items():
        cells = [f"{microseconds_per_update(make, p, args.number, args.repeat):.1f}" for p in SIZES]
        print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
