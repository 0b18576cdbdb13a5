"""Standalone FMUs (``obsfmu build --standalone``): size and first-instantiation time per block kind.

Per kind (the first FMU of each kind among the scenarios), FMI 2.0: the size of the standalone
``.fmu`` and of the default one, the runtime's files and bytes (uncompressed), and the time of the
first ``fmi2Instantiate`` in a fresh C importer process (``tests/fmus/native/importer.c``) inside a root
file system without Python (chroot; the FMU starts its own interpreter and imports numpy and its
code) -- the median of ``--repeat`` processes.  Issue 28's budget: <= 30 MB and <= 1 s per FMU.

Run:  .venv/bin/python benchmarks/standalone_size.py [--repeat N]   (as root: it enters a chroot)
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "fmus" / "native"))

from native_harness import compile_importer  # noqa: E402
from python_free_root import alone_lines, enter_command, first_of_each_kind, make_root, run_in_root, unzip  # noqa: E402

from obsfmu.fmus.scenarios import ensure_fmus  # noqa: E402
from obsfmu.fmus.standalone import describe  # noqa: E402

MB = 1e6


def first_instantiation(prefix, root: Path, unzipped, start, step, repeat: int) -> float:
    times = []
    for k in range(repeat):
        completed = run_in_root(prefix, root, alone_lines(unzipped, start, 1, step, f"/out/{unzipped.instance}.csv"),
                                f"bench{k}")
        line = next(line for line in completed.stdout.splitlines() if line.startswith("instantiate "))
        if line.split()[2] != "ok":
            raise RuntimeError(completed.stdout + completed.stderr)
        times.append(float(line.split()[3]))
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="processes per kind (median; default 3)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="obsfmu_standalone_bench_") as temp:
        temp = Path(temp)
        root = make_root(temp / "root", compile_importer(temp))
        prefix = enter_command(root)
        if prefix is None:
            sys.exit("this process may not chroot: run as root (unshare --mount --map-root-user chroot)")
        print("| kind | FMU | standalone .fmu | default .fmu | runtime: files, uncompressed | first instantiation |")
        print("|---|---|---|---|---|---|")
        for kind, (scenario, instance, model, start) in first_of_each_kind().items():
            fmu = ensure_fmus(scenario, temp / "standalone", standalone=True)[model]
            default = ensure_fmus(scenario, temp / "default")[model]
            facts = describe(fmu)
            seconds = first_instantiation(prefix, root, unzip(root, instance, fmu, kind), start, scenario.step,
                                          args.repeat)
            print(f"| {kind} | {model} | {facts['fmu_bytes'] / MB:.1f} MB | {default.stat().st_size / MB:.2f} MB | "
                  f"{facts['runtime_files']}, {facts['runtime_bytes'] / MB:.1f} MB | {seconds:.3f} s |")


if __name__ == "__main__":
    main()
