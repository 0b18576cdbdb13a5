"""Noise study of the gpebo-observer worked example (examples/gpebo_shift3.toml): `obsfmu sweep`.

The measured output passes through the file's ``added-noise`` component ``sensor`` (Gaussian, one
new sample per plant sample).  Two sweeps over ``sensor.std`` x 10 seeds, 60 samples each:

* ``restart_tol = 1e-11`` (the default, tuned for exact data), and
* ``restart_tol = 1e-4`` (against noise: the filters are not restarted by noise-driven jitter of
  ``gamma_hat``),

each ``obsfmu sweep --config examples/gpebo_shift3.toml --vary sensor.std=[...] --vary
sensor.seed=0:9:10 --set observer.restart_tol=...``.  The figure (docs/figures/noise_gpebo.png) shows
the final error ``max |x - x_hat|`` (over x and theta) and the convergence time (every error below the
file's tolerance, 1e-4, for good) against the noise level; the numbers are printed.

    .venv/bin/python benchmarks/noise_gpebo.py [--out results/noise-gpebo] [--workers 2]
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "gpebo_shift3.toml"
STDS = [0.0, 1e-9, 1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3]
SETTINGS = {"restart_tol = 1e-11 (default)": "1e-11", "restart_tol = 1e-4": "1e-4"}


def sweep(out: Path, restart_tol: str, workers: int) -> list[dict]:
    command = [sys.executable, "-m", "fmus.cli", "sweep", "--config", str(EXAMPLE),
               "--vary", "sensor.std=[" + ",".join(repr(s) for s in STDS) + "]", "--vary", "sensor.seed=0:9:10",
               "--set", f"observer.restart_tol={restart_tol}", "--workers", str(workers), "--out", str(out),
               "--no-progress", "--no-plots", "--build-dir", str(out.parent / "build")]
    subprocess.run(command, cwd=ROOT, check=True, stdout=subprocess.DEVNULL)
    with open(out / "samples.csv", newline="") as handle:
        return list(csv.DictReader(handle))


def by_std(rows: list[dict], key: str) -> list[np.ndarray]:
    return [np.array([float(r[key]) for r in rows if float(r["sensor.std"]) == std]) for std in STDS]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "noise-gpebo")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--figure", type=Path, default=ROOT / "docs" / "figures" / "noise_gpebo.png")
    args = parser.parse_args()
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (left, right) = plt.subplots(1, 2, figsize=(9, 3.6))
    x = np.array([s if s > 0 else 1e-10 for s in STDS])          # std 0 drawn at 1e-10
    for j, (label, restart_tol) in enumerate(SETTINGS.items()):
        rows = sweep(args.out / f"restart_tol_{restart_tol}", restart_tol, args.workers)
        errors, times = by_std(rows, "final_error"), by_std(rows, "convergence_time")
        print(f"{label}:")
        for std, e, t in zip(STDS, errors, times):
            finite = t[np.isfinite(t)]
            print(f"  std {std:8.1e}: final error median {np.median(e):.1e} (max {np.max(e):.1e}); converged "
                  f"{finite.size}/{t.size}" + (f", time median {np.median(finite):g} s" if finite.size else ""))
        shift = 1.15 if j else 1 / 1.15
        left.errorbar(x * shift, [np.median(e) for e in errors],
                      yerr=[[np.median(e) - np.min(e) for e in errors], [np.max(e) - np.median(e) for e in errors]],
                      fmt="o-", capsize=3, label=label)
        for std, t in zip(x, times):
            finite = t[np.isfinite(t)]
            right.plot(np.full(finite.size, std * shift), finite, "o", color=f"C{j}", alpha=0.4, ms=4,
                       label=label if std == x[0] else None)
    left.set(xscale="log", yscale="log", xlabel="noise std on y (std 0 at 1e-10)", ylabel="final max |error|",
             title="final error (median, min-max of 10 seeds)")
    right.set(xscale="log", xlabel="noise std on y", ylabel="convergence time (samples)",
              title="convergence to 1e-4 (converged seeds only)")
    left.legend(fontsize=8)
    right.legend(fontsize=8)
    figure.tight_layout()
    args.figure.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(args.figure, dpi=80)
    print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()
