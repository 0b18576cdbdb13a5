"""Noise study of paper 001's observer on its worked examples (docs/adaptive-ltv.md).

An ``obsfmu sweep`` of an example over the standard deviation of the sensor noise on ``y`` (the
``added-noise`` component ``sensor``, seeded), a few seeds per level and forgetting factors of the
least-squares estimator (``observer.beta``).  The convergence time is that of the example's estimated
parameters (``EXAMPLES[...].columns``: stiffness and damping ``k_hat`` of the mass-spring-damper; the
stiffness and cubic coefficient in ``m_hat`` of the drifting sensor) to ``TOLERANCE`` (the example's
compare tolerances, 1e-3, are replaced by it in a copy of the file: with noise the estimates do not stay
within 1e-3); the final error is the largest of them at 30 s.  Writes docs/figures/noise_ltv.png
(``--example drifting``: noise_ltv_drifting.png) and prints the table of the docs.

    python benchmarks/noise_ltv.py [--example msd|drifting] [--out DIR] [--workers 2]

Not a test (msd: about 60 runs, ~8 min on the shared 2-core machine; drifting: 24 runs).
"""

from __future__ import annotations

import argparse
import csv
import math
import subprocess
import sys
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TOLERANCE = 1e-2


@dataclass(frozen=True)
class Example:
    file: str
    columns: tuple[str, ...]          #: the estimates whose final error and convergence time are measured
    label: str                        #: what they are, in the table and the figure
    stds: tuple[float, ...]
    seeds: tuple[int, ...]
    betas: tuple[float, ...]
    figure: str
    title: str


EXAMPLES = {
    "msd": Example("ltv_mass_spring_damper.toml", ("observer.k_hat[1]", "observer.k_hat[2]"), "k_hat - k",
                   (0.0, 1e-4, 1e-3, 3e-3, 1e-2, 3e-2), (1, 2, 3, 4, 5), (0.5, 0.1), "noise_ltv.png",
                   "paper 001 observer, mass-spring-damper: noise study"),
    "drifting": Example("ltv_drifting_sensor.toml", ("observer.m_hat[2]", "observer.m_hat[6]"), "m_hat - m",
                        (0.0, 1e-4, 1e-3, 1e-2), (1, 2, 3), (0.5, 0.1), "noise_ltv_drifting.png",
                        "paper 001 observer, drifting sensor, three f_i: noise study"),
}


def study_file(example: Example, folder: Path) -> Path:
    """The example with its compare tolerances set to TOLERANCE."""
    text = (ROOT / "examples" / example.file).read_text()
    assert text.count("\ntolerance = 1e-3\n") == 3, "the example's [[report.compare]] tables changed"
    path = folder / example.file.replace(".toml", "_noise.toml")
    path.write_text(text.replace("\ntolerance = 1e-3\n", f"\ntolerance = {TOLERANCE:g}\n"))
    return path


def sweep(example: Example, out: Path, workers: int) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    command = [sys.executable, "-m", "obsfmu", "sweep", "--config", str(study_file(example, out)),
               "--vary", f"sensor.std=[{', '.join(map(repr, example.stds))}]",
               "--vary", f"sensor.seed=[{', '.join(map(str, example.seeds))}]",
               "--vary", f"observer.beta=[{', '.join(map(repr, example.betas))}]",
               "--workers", str(workers), "--out", str(out / "sweep"), "--no-plots", "--no-progress"]
    subprocess.run(command, check=True, cwd=ROOT)
    return out / "sweep" / "samples.csv"


def read(example: Example, samples: Path) -> dict[tuple[float, float], list[tuple[float, float]]]:
    """(std, beta) -> [(final error, convergence time)] of the finished samples."""
    found = defaultdict(list)
    with samples.open() as handle:
        for row in csv.DictReader(handle):
            if row["status"] != "ok":
                continue
            error = max(float(row[f"final_error {c}"]) for c in example.columns)
            time = max(float(row[f"convergence_time {c}"]) for c in example.columns)
            found[(float(row["sensor.std"]), float(row["observer.beta"]))].append((error, time))
    return found


def table(example: Example, found) -> list[str]:
    lines = [f"| noise std on y | beta | final max abs({example.label}): median (max) | within 1e-2 from: median (max), "
             "s |", "|---|---|---|---|"]
    for (std, beta), rows in sorted(found.items()):
        errors, times = np.array(rows).T
        reached = times[np.isfinite(times)]
        time = (f"{np.median(times):.1f} ({times.max():.1f})" if reached.size == times.size else
                f"{reached.size} of {times.size} reach it"
                + (f", median {np.median(reached):.1f}" if reached.size else ""))
        lines.append(f"| {std:g} | {beta:g} | {np.median(errors):.2e} ({errors.max():.2e}) | {time} |")
    return lines


def figure(example: Example, found, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(6.4, 6.0), sharex=True)
    floor = 0.3 * min(s for s in example.stds if s > 0)
    for index, beta in enumerate(example.betas):
        shift = 1.0 + 0.12 * (index - 0.5)
        for std in example.stds:
            rows = found.get((std, beta), [])
            if not rows:
                continue
            errors, times = np.array(rows).T
            x = np.full(errors.size, (std or floor) * shift)
            top.scatter(x, errors, s=14, color=f"C{index}", label=f"beta = {beta:g} 1/s" if std == example.stds[0] else None)
            finite = np.isfinite(times)
            bottom.scatter(x[finite], times[finite], s=14, color=f"C{index}")
            bottom.scatter(x[~finite], np.full((~finite).sum(), 31.0), s=18, marker="^", color=f"C{index}")
    top.set_xscale("log")
    top.set_yscale("log")
    top.set_ylabel(f"final max |{example.label}| at 30 s")
    top.legend(loc="upper left")
    top.grid(True, which="both", alpha=0.3)
    bottom.set_ylabel(f"within {TOLERANCE:g} from, s\n(triangles: not within 30 s)")
    bottom.set_xlabel(f"noise std on y, m (0 drawn at {floor:g})")
    bottom.grid(True, which="both", alpha=0.3)
    fig.suptitle(example.title, fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--example", choices=sorted(EXAMPLES), default="msd")
    parser.add_argument("--out", type=Path, default=None, help="default: results/noise_ltv[_drifting]")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--figure", type=Path, default=None, help="default: docs/figures/<the example's figure>")
    args = parser.parse_args()
    example = EXAMPLES[args.example]
    out = args.out or Path("results/noise_ltv" + ("" if args.example == "msd" else f"_{args.example}"))
    path = args.figure or ROOT / "docs" / "figures" / example.figure
    found = read(example, sweep(example, out, args.workers))
    figure(example, found, path)
    print("\n".join(table(example, found)))
    print(f"wrote {path} ({path.stat().st_size / 1024:.0f} kB)")


if __name__ == "__main__":
    sys.exit(main())
