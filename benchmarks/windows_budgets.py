"""The budgets of win64 FMUs (issue 35), measured in one run: sizes, first instantiation under wine, per-step cost.

* size of a win64 FMU (``--platform win64``) and of a dual-platform one (``--platform linux64,win64``, with and
  without ``--standalone`` for the Linux part): budgets 25 MB and 45 MB;
* the first ``fmi2Instantiate`` of a fresh Windows C host under wine (``importer.exe``, no Python in the process:
  the FMU starts the Windows CPython it carries and imports numpy and its code), median of 3: budget 2 s;
* per-step cost (``fmi2DoStep`` through the bridge, the importer's ``bench``) of the same dual-platform
  standalone FMU under wine and on Linux (the C importer in an empty environment): budget 1.5x.

Run:  .venv/bin/python benchmarks/windows_budgets.py [--calls N] [--repeat K]
(needs Debian's mingw-w64 and wine64; the Windows CPython and numpy are fetched once into the cache).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "fmus" / "native"))

from native_harness import Unzipped, compile_importer, run as run_importer  # noqa: E402
from windows_harness import Wine, windows_importer, windows_path  # noqa: E402

from obsfmu.fmus.scenarios import ensure_fmus, get  # noqa: E402

MODELS = {"ship": ("ship_plant", "ship_observer"), "ltv-ls-bounded": ("ltv_ls_bounded_observer",)}


def built(root: Path, **options) -> dict[str, Path]:
    found = {}
    for name, models in MODELS.items():
        fmus = ensure_fmus(get(name), root, **options)
        found.update({model: fmus[model] for model in models})
    return found


def sizes(root: Path) -> dict[str, dict[str, float]]:
    variants = {"win64": dict(platforms="win64"), "linux64,win64": dict(platforms="linux64,win64"),
                "linux64,win64 --standalone": dict(platforms="linux64,win64", standalone=True)}
    return {label: {model: path.stat().st_size / 1e6 for model, path in built(root / label.replace(" ", "_").replace(",", "+"),
                                                                                **options).items()}
            for label, options in variants.items()}


def bench_lines(unzipped: Unzipped, calls: int, host_path=str) -> list[str]:
    inputs = [v.name for v in unzipped.description.modelVariables if v.causality == "input"]
    output = next(v.name for v in unzipped.description.modelVariables if v.causality == "output")
    vr_in = unzipped.vr(inputs[0]) if inputs else unzipped.vr(output)
    return [unzipped.declaration(host_path), f"bench {unzipped.instance} {vr_in} {unzipped.vr(output)} {calls}"]


def parse(stdout: str) -> tuple[float, float]:
    """(first instantiation, seconds per fmi2DoStep) of a bench run."""
    first = next(float(line.split()[3]) for line in stdout.splitlines() if line.startswith("instantiate "))
    step = next(float(line.split()[3]) for line in stdout.splitlines() if "fmi2DoStep " in line)
    return first, step


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--calls", type=int, default=2000, help="fmi2DoStep calls per bench (default 2000)")
    parser.add_argument("--repeat", type=int, default=3, help="fresh processes per measurement (default 3)")
    options = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="obsfmu_windows_budgets_") as temp:
        root = Path(temp)
        print("FMU size (MB):")
        for label, models in sizes(root).items():
            print(f"  {label:28s} " + ", ".join(f"{m} {s:.1f}" for m, s in models.items()))
        fmus = built(root / "linux64+win64_--standalone", platforms="linux64,win64", standalone=True)
        wine, linux = Wine(root / "wine"), compile_importer(root)
        windows = windows_importer(root)
        wine.run(windows)                                  # the prefix is made once, outside the measurements
        print(f"first instantiation and fmi2DoStep ({options.calls} calls), median of {options.repeat} fresh "
              "processes each:")
        for model, fmu in fmus.items():
            unzipped = Unzipped.of(model, fmu, root / "unzipped" / model)
            results = {"wine": [], "linux": []}
            for k in range(options.repeat):
                script = root / f"{model}{k}.txt"
                script.write_text("\n".join(bench_lines(unzipped, options.calls, windows_path)) + "\n")
                completed = wine.run(windows, windows_path(script))
                assert completed.returncode == 0, completed.stdout[-2000:] + completed.stderr[-2000:]
                results["wine"].append(parse(completed.stdout))
                completed = run_importer(linux, bench_lines(unzipped, options.calls), root)
                assert completed.returncode == 0, completed.stdout[-2000:] + completed.stderr[-2000:]
                results["linux"].append(parse(completed.stdout))
            first = {side: statistics.median(r[0] for r in runs) for side, runs in results.items()}
            step = {side: statistics.median(r[1] for r in runs) for side, runs in results.items()}
            print(f"  {model:26s} first: wine {first['wine']:.3f} s, linux {first['linux']:.3f} s;  "
                  f"step: wine {1e6 * step['wine']:.1f} us, linux {1e6 * step['linux']:.1f} us, "
                  f"ratio {step['wine'] / step['linux']:.2f}")
        wine.close()


if __name__ == "__main__":
    main()
