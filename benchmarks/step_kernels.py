"""Compiled step kernels against the Python path and against compiled FMUs, per step, side by side in one run
(issue 39; the table in docs/performance.md).

Measured in fmusim (Modelica Reference-FMUs 0.0.39, ``../shared/vendor``), writing its CSV every step: the cost
of one step is ``(T(N2) - T(N1)) / (N2 - N1)``, each ``T`` the best of ``--repeat`` runs of the whole process
(start-up and instantiation cancel).  Rows:

* Reference-FMUs Dahlquist and VanDerPol (compiled C), built here with ``cc`` from a checkout of
  github.com/modelica/Reference-FMUs (``--reference-fmus DIR``; rows left out without it);
and in a bare C host (this file: ``fmi2DoStep`` and ``fmi2GetReal`` of the outputs in a loop, nothing else), what
the FMU itself costs.

* the ship FMUs (paper 002: LTI plant, Luenberger observer, state feedback) with their kernel and with
  ``--kernels python``; an ``expression`` plant, the forced Duffing oscillator of benchmarks/expression_plant.py
  (RK4 sub-steps of at most 1e-3 s under error control, its expressions compiled to C), against VanDerPol;
  ``ltv_ls_observer`` (paper 001's example, least squares, its ``A(t)``, ``L(t)``, ``f`` compiled to C) with its
  kernel and with ``--kernels python`` (fmusim's inputs stay 0: the same operations per step as in the scenario).

Through the project's master: CPU per communication step of ``ship`` and of the integrator chains of order 2..50
(a signal source, the chain, its observer: benchmarks/high_order.py) with and without kernels
(``OBSFMU_KERNELS=python``), the two sessions in this process, their runs interleaved (best of ``--repeat``; a run's
set-up not counted, :func:`benchmarks.cosimulation_costs.per_step_case`).  And ``obsfmu run ship`` (the master,
50 000 steps of three FMUs) with and without kernels, as wall time of the process.

    python benchmarks/step_kernels.py --reference-fmus ~/src/Reference-FMUs [--fmusim PATH]

``fmusim``: ``--fmusim``, else the one the third-party tests built (``~/.cache/obsfmu/importers/*/fmusim``).
"""

from __future__ import annotations

import argparse
import glob
import os
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SHIP = ROOT / "fmus" / "scenarios" / "ship" / "system.toml"
LTV_LS = ROOT / "fmus" / "scenarios" / "ltv_ls" / "system.toml"
HOST = {"linux": "linux64", "darwin": "darwin64"}.get(sys.platform, "linux64")
#: the forced Duffing oscillator of benchmarks/expression_plant.py
DUFFING = ["x[2]", "-delta * x[2] - alpha * x[1] - beta * x[1] ** 3 + gain * u[1]"]
DUFFING_PARAMETERS = {"delta": 0.3, "alpha": -1.0, "beta": 1.0, "gain": 0.8}


def find_fmusim(given: str | None) -> str:
    candidates = [given] if given else sorted(glob.glob(os.path.expanduser("~/.cache/obsfmu/importers/*/fmusim")))
    candidates += [shutil.which("fmusim") or ""]
    for candidate in candidates:
        if candidate and subprocess.run([candidate, "--help"], capture_output=True, check=False).returncode in (0, 1):
            return candidate
    sys.exit("fmusim not found: pass --fmusim, or build it (pytest tests/fmus/native/test_third_party.py)")


def reference_fmu(checkout: Path, model: str, out: Path) -> Path:
    """``<model>.fmu`` (FMI 2.0 co-simulation) compiled from a Reference-FMUs checkout, as its CMake build does."""
    folder = out / model
    binary = folder / "binaries" / HOST / f"{model}.so"
    binary.parent.mkdir(parents=True, exist_ok=True)
    subprocess.run([os.environ.get("CC", "cc"), "-shared", "-fPIC", "-O2", "-DFMI_VERSION=2", "-DDISABLE_PREFIX",
                    "-I", str(checkout / "include"), "-I", str(checkout / model),
                    str(checkout / "src" / "fmi2Functions.c"), str(checkout / "src" / "cosimulation.c"),
                    str(checkout / model / "model.c"), "-o", str(binary), "-lm"], check=True)
    fmu = out / f"{model}.fmu"
    with zipfile.ZipFile(fmu, "w") as archive:
        archive.write(checkout / model / "FMI2.xml", "modelDescription.xml")
        archive.write(binary, f"binaries/{HOST}/{model}.so")
    return fmu


#: a bare FMI 2.0 host: instantiate, initialise, then N times fmi2DoStep + fmi2GetReal of the outputs; prints
#: nanoseconds per step of that loop alone (what the FMU costs, without an importer's own work)
BARE_HOST = r"""
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "fmi2Functions.h"
static void logger(fmi2ComponentEnvironment e, fmi2String n, fmi2Status s, fmi2String c, fmi2String m, ...)
{ (void)e; (void)n; (void)c; if (s > fmi2Warning) fprintf(stderr, "%s\n", m); }
#define BIND(name) name##TYPE *name = (name##TYPE *)dlsym(so, #name)
int main(int argc, char **argv)
{
    /* library guid resources-uri steps h vr... */
    void *so = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!so) { fprintf(stderr, "%s\n", dlerror()); return 2; }
    BIND(fmi2Instantiate); BIND(fmi2SetupExperiment); BIND(fmi2EnterInitializationMode);
    BIND(fmi2ExitInitializationMode); BIND(fmi2DoStep); BIND(fmi2GetReal); BIND(fmi2FreeInstance);
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component c = fmi2Instantiate("bare", fmi2CoSimulation, argv[2], argv[3], &callbacks, fmi2False, fmi2False);
    long steps = atol(argv[4]); double h = atof(argv[5]);
    int n = argc - 6; fmi2ValueReference vr[64]; double out[64];
    for (int i = 0; i < n && i < 64; i++) vr[i] = (fmi2ValueReference)atol(argv[6 + i]);
    if (!c || fmi2SetupExperiment(c, fmi2False, 0, 0, fmi2False, 0) > fmi2Warning ||
        fmi2EnterInitializationMode(c) > fmi2Warning || fmi2ExitInitializationMode(c) > fmi2Warning) return 3;
    struct timespec a, b;
    clock_gettime(CLOCK_MONOTONIC, &a);
    for (long k = 0; k < steps; k++)
        if (fmi2DoStep(c, k * h, h, fmi2True) > fmi2Warning || fmi2GetReal(c, vr, n, out) > fmi2Warning) return 4;
    clock_gettime(CLOCK_MONOTONIC, &b);
    printf("%.1f\n", ((b.tv_sec - a.tv_sec) * 1e9 + (b.tv_nsec - a.tv_nsec)) / steps);
    fmi2FreeInstance(c);
    return 0;
}
"""


def bare_host(work: Path) -> Path:
    import fmpy
    source, program = work / "bare_host.c", work / "bare_host"
    source.write_text(BARE_HOST)
    subprocess.run([os.environ.get("CC", "cc"), "-O2", "-I", str(Path(fmpy.__file__).parent / "c-code"), str(source),
                    "-o", str(program), "-ldl"], check=True)
    return program


def bare_per_step(host: Path, fmu: Path, step: float, steps: int, repeat: int, work: Path) -> float:
    """Microseconds per fmi2DoStep + fmi2GetReal(outputs) in the bare host (best of ``repeat``)."""
    from fmpy import read_model_description
    folder = work / ("unzipped_" + fmu.parent.name + "_" + fmu.stem)
    if not folder.exists():
        zipfile.ZipFile(fmu).extractall(folder)
    description = read_model_description(str(fmu))
    outputs = [str(v.valueReference) for v in description.modelVariables if v.causality == "output"]
    identifier = description.coSimulation.modelIdentifier
    command = [str(host), str(folder / "binaries" / HOST / f"{identifier}.so"), description.guid,
               (folder / "resources").as_uri(), str(steps), repr(step), *outputs]
    return min(float(subprocess.run(command, check=True, capture_output=True, text=True).stdout) for _ in range(repeat)) / 1e3


def run_time(command: list[str], repeat: int, env=None) -> float:
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        subprocess.run(command, check=True, capture_output=True, env=env)
        best = min(best, time.perf_counter() - start)
    return best


def per_step(fmusim: str, fmu: Path, step: float, steps: tuple[int, int], repeat: int, out: Path, env=None) -> float:
    """Microseconds per step in fmusim, CSV written every step."""
    times = []
    for n in steps:
        command = [fmusim, "--interface-type", "cs", "--stop-time", repr(n * step), "--output-interval", repr(step),
                   "--output-file", str(out / "out.csv"), str(fmu)]
        times.append(run_time(command, repeat, env))
    return (times[1] - times[0]) / (steps[1] - steps[0]) * 1e6


def master_per_step(repeat: int, work: Path) -> list[tuple[str, float, float]]:
    """``(case, us per step with kernels, us per step on the Python path)`` through the master (module docstring)."""
    sys.path.insert(0, str(ROOT))
    from obsfmu.fmus.config import design_from_config
    from obsfmu.fmus.scenarios import get

    from benchmarks.cosimulation_costs import CHAIN_OBSERVER, per_step_case
    from benchmarks.high_order import chain_config, input_system
    ship = get("ship")
    cases = [("ship", ship.definitions(), ship.components, ship.connections, ship.step)]
    for n in (2, 5, 10, 20, 50):
        definitions, components, connections = input_system(design_from_config(chain_config(n, CHAIN_OBSERVER(n))))
        cases.append((f"chain n = {n}", definitions, components, connections, 1e-3))
    rows = []
    for label, definitions, components, connections, step in cases:
        paths = {}
        for kernels in ("python", "c"):                    # the environment is read when an instance is made
            os.environ["OBSFMU_KERNELS"] = kernels
            paths[kernels] = per_step_case(label, definitions, components, connections, step, work / "master")
        os.environ.pop("OBSFMU_KERNELS")
        best = {"c": float("inf"), "python": float("inf")}
        for _ in range(repeat):
            for kernels, steps in (("c", 20000), ("python", 2000)):
                best[kernels] = min(best[kernels], paths[kernels][1]["fmu"](steps))
        for session, _ in paths.values():
            session.close()
        rows.append((label, best["c"] * 1e6, best["python"] * 1e6))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--reference-fmus", type=Path, help="a checkout of github.com/modelica/Reference-FMUs")
    parser.add_argument("--fmusim", help="the fmusim executable")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--steps", type=int, nargs=2, default=(2000, 202000), metavar=("N1", "N2"))
    parser.add_argument("--ltv-steps", type=int, nargs=2, default=(200, 2200), metavar=("N1", "N2"))
    # fmusim's inputs stay 0: unexcited, P decays as e^{-t} and meets the gain bound M = 1e12 at t ~ 25 s, after which
    # the observer steps in Python (F frozen); 22 000 steps of 1e-3 s stay before it
    parser.add_argument("--ltv-kernel-steps", type=int, nargs=2, default=(2000, 22000), metavar=("N1", "N2"))
    args = parser.parse_args()
    fmusim = find_fmusim(args.fmusim)
    obsfmu = [sys.executable, "-m", "obsfmu"]
    with tempfile.TemporaryDirectory() as temp:
        work = Path(temp)
        subprocess.run(obsfmu + ["build", "--config", str(SHIP), "--out", str(work / "c")], check=True,
                       capture_output=True)
        subprocess.run(obsfmu + ["build", "--config", str(SHIP), "--out", str(work / "python"), "--kernels",
                                 "python"], check=True, capture_output=True)
        subprocess.run(obsfmu + ["build", "--out", str(work / "all")], check=True, capture_output=True)
        for kernels in ("c", "python"):
            subprocess.run(obsfmu + ["build", "--config", str(LTV_LS), "--out", str(work / f"ltv_{kernels}"),
                                     "--kernels", kernels], check=True, capture_output=True)
        from obsfmu.fmus.builder import build_fmu
        from obsfmu.fmus.runtime.kinds.expression import expression_plant_definition
        from obsfmu.fmus.runtime.kinds.noise import noise_source_definition
        for kernels in ("c", "python"):
            duffing = expression_plant_definition("duffing", DUFFING, ["x[1]"], [1.0, 0.0], inputs=1,
                                                  parameters=DUFFING_PARAMETERS)
            # white noise, two streams, a new sample every step: a fresh default_rng((seed, k)) each step
            noise = noise_source_definition("white_noise", std=1.0, sample_interval=1e-3, seed=1, size=2)
            for definition in (duffing, noise):
                definition.kernels = kernels
                build_fmu(definition, work / kernels)
        host = bare_host(work)
        rows = []

        def measure(label, fmu, step, steps):
            rows.append((label, per_step(fmusim, fmu, step, steps, args.repeat, work),
                         bare_per_step(host, fmu, step, steps[1], args.repeat, work)))
        if args.reference_fmus:
            for model in ("Dahlquist", "VanDerPol"):
                measure(f"Reference-FMUs {model} (compiled C)",
                        reference_fmu(args.reference_fmus, model, work / "reference"), 1e-3, args.steps)
        for model in ("ship_plant", "ship_observer", "ship_controller"):
            for kernels in ("c", "python"):
                # h = 1e-5: the unstable ship (eig(A) = {1, 2}) stays O(1) over the run; CSV numbers of similar size
                measure(f"`{model}`, kernels {kernels}", work / kernels / f"{model}.fmu", 1e-5, args.steps)
        for kernels in ("c", "python"):
            measure(f"`duffing` expression plant, kernels {kernels}", work / kernels / "duffing.fmu", 1e-3,
                    args.steps if kernels == "c" else args.ltv_steps)
        for kernels in ("c", "python"):
            measure(f"`white_noise` (2 streams, a sample per step), kernels {kernels}",
                    work / kernels / "white_noise.fmu", 1e-3, args.steps if kernels == "c" else args.ltv_steps)
        for kernels in ("c", "python"):
            measure(f"`ltv_ls_observer`, kernels {kernels}", work / f"ltv_{kernels}" / "ltv_ls_observer.fmu", 1e-3,
                    args.ltv_kernel_steps if kernels == "c" else args.ltv_steps)
        base = rows[0] if args.reference_fmus else None
        print("| FMU | fmusim, us/step | ratio to Dahlquist | bare C host, doStep + getReal, us | ratio |\n"
              "|---|---|---|---|---|")
        for label, cost, bare in rows:
            ratios = (f"{cost / base[1]:.1f}", f"{bare / base[2]:.0f}") if base else ("-", "-")
            print(f"| {label} | {cost:.2f} | {ratios[0]} | {bare:.3f} | {ratios[1]} |")
        print("\n| through the master, CPU per step | kernels, us | Python path, us | ratio |\n|---|---|---|---|")
        for label, fast, slow in master_per_step(args.repeat, work):
            print(f"| {label} | {fast:.1f} | {slow:.1f} | {slow / fast:.1f}x |")
        env = dict(os.environ)
        master = {}
        for kernels in ("c", "python"):
            env["OBSFMU_KERNELS"] = kernels
            master[kernels] = run_time(obsfmu + ["run", "ship", "--build-dir", str(work / "all")], args.repeat, env)
        print(f"\nobsfmu run ship (50 000 steps, 3 FMUs, process wall time): kernels {master['c']:.2f} s, "
              f"python {master['python']:.2f} s: {master['python'] / master['c']:.1f}x")


if __name__ == "__main__":
    main()
