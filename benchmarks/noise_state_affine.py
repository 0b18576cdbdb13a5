"""Noise study of the paper-004 observer on its worked example (``examples/state_affine_vanderpol.toml``).

    /work/venv/bin/python benchmarks/noise_state_affine.py [--out DIR] [--workers 2] [--report-only]

Two ``obsfmu sweep`` campaigns of the example (seeded Gaussian noise added to the measured position by
its ``sensor`` component, held over 1e-3 s):

* ``noise``: ``sensor.std`` over 0, 1e-5, 1e-4, 1e-3, 1e-2 (the position's amplitude is ~2) times the
  seeds 1..5;
* ``gamma``: at ``sensor.std = 1e-3``, the estimator gain ``observer.gamma`` over 1e8 .. 1e11 times the
  seeds 1..3 (what a user trades against noise).

It prints per level the median and largest final parameter error and the convergence times (from when
``|theta_hat - theta|`` stays below 1e-3), and writes ``docs/figures/noise_state_affine.png``: final error
and convergence time against the noise level, one point per seed.  ``--report-only`` re-reads the
campaigns in ``--out`` (default ``results/noise_state_affine``).  Not part of the test suite (minutes).
"""

from __future__ import annotations

import argparse
import csv
import math
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "state_affine_vanderpol.toml"
FIGURE = ROOT / "docs" / "figures" / "noise_state_affine.png"
ESTIMATES = ("observer.theta_hat[1]", "observer.theta_hat[2]")
STUDIES = {
    "noise": ("sensor.std", ["--vary", "sensor.std=[0, 1e-5, 1e-4, 1e-3, 1e-2]", "--vary", "sensor.seed=[1,2,3,4,5]"]),
    "gamma": ("observer.gamma", ["--set", "sensor.std=1e-3", "--vary", "observer.gamma=[1e8, 1e9, 1e10, 1e11]",
                                 "--vary", "sensor.seed=[1,2,3]"]),
}


def sweep(out: Path, study: str, workers: int) -> None:
    command = [sys.executable, "-m", "obsfmu", "sweep", "--config", str(EXAMPLE), *STUDIES[study][1],
               "--workers", str(workers), "--no-progress", "--no-plots", "--out", str(out / study)]
    subprocess.run(command, cwd=ROOT, check=True)


def samples(out: Path, study: str) -> dict[float, list[tuple[float, float]]]:
    """Per value of the study's variable: (final theta error, convergence time) of each sample."""
    varied = STUDIES[study][0]
    rows = defaultdict(list)
    with open(out / study / "samples.csv", newline="") as handle:
        for row in csv.DictReader(handle):
            if row["status"] != "ok":
                rows[float(row[varied])].append((math.inf, math.inf))
                continue
            final = max(float(row[f"final_error {e}"]) for e in ESTIMATES)
            converged = max(float(row[f"convergence_time {e}"]) for e in ESTIMATES)
            rows[float(row[varied])].append((final, converged))
    return dict(sorted(rows.items()))


def _median(values: list[float]) -> float:
    ordered = sorted(values)
    middle = len(ordered) // 2
    return ordered[middle] if len(ordered) % 2 else 0.5 * (ordered[middle - 1] + ordered[middle])


def report(study: str, table: dict) -> None:
    print(f"\n{study}: {STUDIES[study][0]} | median / max final |theta_hat - theta| | convergence time (1e-3): "
          "median / max | converged samples")
    for level, values in table.items():
        finals, times = [v[0] for v in values], [v[1] for v in values]
        reached = sum(math.isfinite(t) for t in times)
        print(f"  {level:8.0e} | {_median(finals):.2e} / {max(finals):.2e} | {_median(times):.3g} / {max(times):.3g} s"
              f" | {reached}/{len(values)}")


def figure(noise: dict, gamma: dict) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(11, 3.2), dpi=80)
    floor = 1e-6                                    # std = 0 drawn at the left edge of the log axis
    for level, values in noise.items():
        x = max(level, floor)
        axes[0].scatter([x] * len(values), [v[0] for v in values], s=14, color="C0")
        times = [v[1] if math.isfinite(v[1]) else 8.0 for v in values]
        axes[1].scatter([x] * len(values), times, s=14, color=["C1" if math.isfinite(v[1]) else "C3" for v in values])
    for level, values in gamma.items():
        axes[2].scatter([level] * len(values), [v[0] for v in values], s=14, color="C2")
    axes[0].set(xscale="log", yscale="log", xlabel="noise std on y (std 0 at 1e-6)", ylabel="final |theta_hat - theta|",
                title="final parameter error")
    axes[1].set(xscale="log", xlabel="noise std on y", ylabel="s", ylim=(0, 8.5),
                title="time to stay within 1e-3 (red: never, at 8 s)")
    axes[2].set(xscale="log", yscale="log", xlabel="gamma (std 1e-3)", ylabel="final |theta_hat - theta|",
                title="estimator gain against noise")
    for axis in axes:
        axis.grid(True, which="both", alpha=0.3)
    fig.suptitle("paper-004 observer, Van der Pol example: measurement noise (5 seeds per level; gain study: 3 seeds "
                 "at std 1e-3)", fontsize=10)
    fig.tight_layout()
    FIGURE.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(FIGURE)
    print(f"\nwrote {FIGURE} ({FIGURE.stat().st_size // 1024} kB)")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "noise_state_affine")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--report-only", action="store_true", help="re-read the campaigns in --out, run nothing")
    args = parser.parse_args(argv)
    tables = {}
    for study in STUDIES:
        if not args.report_only:
            sweep(args.out, study, args.workers)
        tables[study] = samples(args.out, study)
        report(study, tables[study])
    figure(tables["noise"], tables["gamma"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
