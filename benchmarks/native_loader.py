"""The portable FMU binary (loader + bridge, fmus/native) measured in one run.

* agreement of a C host (tests/fmus/native/importer.c, no libpython, empty environment) with our Jacobi
  master on ``ship`` (0.2 s, h = 1e-4) and ``ltv-ls-bounded`` (2 s, h = 1e-3);
* first and second instantiation of ``ship_observer`` in a C host (the FMU starts Python and
  imports numpy/scipy and its code) and in a fresh Python process under fmpy (Python running);
* per-call cost of the loader: a call it answers alone (``fmi2GetRealStatus``: state check +
  forwarding layer) against calls that go through the bridge into Python (``fmi2GetReal`` of one
  output, ``fmi2DoStep``) -- an upper bound of the indirection's share.

Run:  .venv/bin/python benchmarks/native_loader.py [--calls N]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "fmus" / "native"))

from native_harness import Unzipped, compile_importer, read_csv, run as run_importer, system_script  # noqa: E402

from obsfmu.fmus.scenarios import ensure_fmus, get, run  # noqa: E402

RUNS = {"ship": (0.2, 1e-4), "ltv-ls-bounded": (2.0, 1e-3)}


def agreement(importer: Path, build: Path, work: Path) -> dict[str, float]:
    lines, files = [], {}
    for name, (stop, step) in RUNS.items():
        scenario = get(name)
        fmus = ensure_fmus(scenario, build)
        unzipped = [Unzipped.of(i, fmus[m], work / name) for i, m, _ in scenario.components]
        files[name] = work / f"{name}.csv"
        lines += system_script(unzipped, scenario.connections, {i: s for i, _, s in scenario.components})
        lines += [f"cosim jacobi {scenario.coupling} 0 {stop!r} {step!r} {files[name]}", "clear"]
    completed = run_importer(importer, lines, work)
    assert completed.returncode == 0, completed.stderr
    deviations = {}
    for name, (stop, step) in RUNS.items():
        ours = run(name, build, stop_time=stop, step=step, order="jacobi", ramp=0)[0]  # the importer: plain grid
        deviations[name] = float(np.max(np.abs(read_csv(files[name])[:, 1:] - ours.values)))
    return deviations


def c_host(importer: Path, observer: Unzipped, work: Path, calls: int) -> list[str]:
    vrs = f"{observer.vr('y')} {observer.vr('x_hat[1]')}"
    lines = [observer.declaration(), f"bench observer {vrs} {calls}", f"bench observer {vrs} 1"]
    completed = run_importer(importer, lines, work)
    assert completed.returncode == 0, completed.stderr
    measured = [line for line in completed.stdout.splitlines() if line.startswith(("instantiate", "bench"))]
    return measured[:5]  # the second bench is there for its (second) instantiation only


def fmpy_host(path: Path) -> str:
    script = textwrap.dedent(f"""
        import time
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave
        d = read_model_description({str(path)!r})
        times = []
        for k in range(2):
            s = FMU2Slave(guid=d.guid, unzipDirectory=extract({str(path)!r}), instanceName=f"o{{k}}",
                          modelIdentifier=d.coSimulation.modelIdentifier)
            begin = time.perf_counter()
            s.instantiate()
            times.append(time.perf_counter() - begin)
        print(f"fmpy host: first instantiation {{times[0]:.3f}} s, second {{times[1]:.3f}} s")
    """)
    return subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout.strip()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=20000)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as temp:
        work = Path(temp)
        importer = compile_importer(work)
        build = work / "build"
        for name, deviation in agreement(importer, build, work).items():
            print(f"C importer vs Jacobi master, {name}: max |deviation| = {deviation:.3g}")
        observer_fmu = ensure_fmus(get("ship"), build)["ship_observer"]
        for line in c_host(importer, Unzipped.of("observer", observer_fmu, work / "bench"), work, args.calls):
            print("C host:", line)
        print(fmpy_host(observer_fmu))


if __name__ == "__main__":
    main()
