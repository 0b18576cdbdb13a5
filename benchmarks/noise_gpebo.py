"""Noise study of the gpebo-observer worked example (examples/gpebo_shift3.toml): `obsfmu sweep`.

The measured output passes through the file's ``added-noise`` component ``sensor`` (Gaussian, one
new sample per plant sample).  Three sweeps over ``sensor.std`` x 10 seeds, 60 samples each:

* ``restart_tol = 1e-11``, ``k = 1e-8`` (the defaults, tuned for exact data),
* ``restart_tol = 1e-4`` (the filters are not restarted by noise-driven jitter of ``gamma_hat``),
* ``restart_tol = 1e-2``, ``k_gamma = k_eta = 1e-2`` (slower DREM updates average the noise),

each ``obsfmu sweep --config examples/gpebo_shift3.toml --vary sensor.std=[...] --vary
sensor.seed=0:9:10 --set observer.restart_tol=...``.  The figure (docs/figures/noise_gpebo.png) shows
the final error ``max |x - x_hat|`` (over x and theta) and the convergence time (every error below the
file's tolerance, 1e-4, for good) against the noise level; the numbers are printed, with the runs in
which ``converged`` came up while the true error was above ``converged_tolerance`` (blocks in memory).

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
#: label -> the observer's parameters of the setting (restart_tol, k_gamma = k_eta)
SETTINGS = {"default: restart_tol 1e-11, k 1e-8": ("1e-11", "1e-8"),
            "restart_tol 1e-4, k 1e-8": ("1e-4", "1e-8"),
            "restart_tol 1e-2, k 1e-2": ("1e-2", "1e-2")}
TOLERANCE = 1e-6            # the file's converged_tolerance


def sweep(out: Path, setting: tuple[str, str], workers: int) -> list[dict]:
    restart_tol, k = setting
    command = [sys.executable, "-m", "obsfmu", "sweep", "--config", str(EXAMPLE),
               "--vary", "sensor.std=[" + ",".join(repr(s) for s in STDS) + "]", "--vary", "sensor.seed=0:9:10",
               "--set", f"observer.restart_tol={restart_tol}", "--set", f"observer.k_gamma={k}",
               "--set", f"observer.k_eta={k}", "--workers", str(workers), "--out", str(out),
               "--no-progress", "--no-plots", "--build-dir", str(out.parent / "build")]
    subprocess.run(command, cwd=ROOT, check=True, stdout=subprocess.DEVNULL)
    with open(out / "samples.csv", newline="") as handle:
        return list(csv.DictReader(handle))


def false_flags(setting: tuple[str, str], std: float, seeds: int = 10) -> int:
    """Runs (of ``seeds``) in which ``converged = 1`` while the true gamma or eta error exceeds the tolerance.

    The file's blocks in memory (the code the FMUs run), noise added to y with numpy: the sweep does
    not record the true eta (the generator state at the last restart), the plant block has it.
    """
    from obsfmu.fmus.runtime.kinds import create_block
    from obsfmu.fmus.system.inmemory import block_of
    from obsfmu.fmus.system.load import load_system
    from obsfmu.observers.block import Segment

    definitions = {d.model_name.split("_")[-1]: d for d in load_system(EXAMPLE).definitions()}
    observer_definition = definitions["observer"]
    parameters = {p.name: p.array(p.value) for p in observer_definition.parameters}
    parameters.update(restart_tol=np.array(float(setting[0])), k_gamma=np.array(float(setting[1])),
                      k_eta=np.array(float(setting[1])))
    count = 0
    for seed in range(seeds):
        source, plant = block_of(definitions["source"]), block_of(definitions["plant"])
        observer = create_block(observer_definition.kind, parameters, observer_definition.options)
        rng, history, wrong = np.random.default_rng(seed), [plant.xi.copy()], False
        for k in range(60):
            out = observer.outputs(k, {})
            truth = history[int(round(out["restart_time"][0]))]
            if out["converged"][0] and max(np.max(np.abs(out["gamma_hat"] - [-1.0, 1.0])),
                                           np.max(np.abs(out["eta_hat"] - truth))) > TOLERANCE:
                wrong = True
            u = source.outputs(k, {})["y"]
            y = plant.outputs(k, {"u": u})["y"] + std * rng.standard_normal()
            observer.advance(k, 1.0, {"u": Segment.hold(u), "y": Segment.hold(y)})
            plant.advance(k, 1.0, {"u": Segment.hold(u)})
            history.append(plant.xi.copy())
        count += wrong
    return count


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

    figure, (left, right) = plt.subplots(1, 2, figsize=(10, 3.8))
    x = np.array([s if s > 0 else 1e-10 for s in STDS])          # std 0 drawn at 1e-10
    for j, (label, setting) in enumerate(SETTINGS.items()):
        rows = sweep(args.out / f"restart_tol_{setting[0]}_k_{setting[1]}", setting, args.workers)
        errors, times = by_std(rows, "final_error"), by_std(rows, "convergence_time")
        print(f"{label}:")
        for std, e, t in zip(STDS, errors, times):
            finite = t[np.isfinite(t)]
            print(f"  std {std:8.1e}: final error median {np.median(e):.1e} (max {np.max(e):.1e}); converged "
                  f"{finite.size}/{t.size}" + (f", time median {np.median(finite):g} s" if finite.size else "")
                  + f"; false converged flag in {false_flags(setting, std)}/10 runs")
        shift = 1.15 ** (j - 1)
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
