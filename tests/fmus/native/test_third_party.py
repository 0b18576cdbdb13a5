"""The FMUs in importers written by others, built here from their sources (issue 28.6).

``../shared/vendor/`` (beside the checkout; or ``$OBSFMU_VENDOR``) holds fmusim (Reference-FMUs 0.0.39)
and the FMU Compliance Checker with their build scripts (its README).  Each tool is built once into
``$XDG_CACHE_HOME/obsfmu/importers/<hash of its sources>`` (fmuCheck takes ~2 minutes the first time);
without the sources or the Debian packages the tests are skipped with the reason (``.ci/run`` installs
the packages).  Then:

* every FMI 2.0 FMU of the scenarios passes the compliance checker with 0 errors;
* every FMI 2.0 and FMI 3.0 FMU runs in fmusim (the FMI 3.0 ones failed: "fmi3GetFloat64: 16 values
  requested, more than the FMU's 15", fmusim asks for ``time`` too);
* fmusim's saved FMU state: fmusim 0.0.39 frees it with the state itself instead of its address, which
  crashed the host; now that call is refused (the run ends with fmusim's error status, the state file is
  written).  The same fmusim with that one call fixed saves a state at t1 and restores it in a second run
  from t1, which continues like one run through (to 1e-13 relative: its grid starts at t1);
* a simple FMU agrees with fmpy (the project's master is built on it) to 1e-12 relative;
* without step and stop options both tools run an FMU's own ``DefaultExperiment`` (fmuCheck: its start and
  stop only) -- the GPEBO FMUs, which refuse any step but 1 s, included.
The scenarios replayed FMU by FMU in fmusim: ``test_fmusim_replay.py``.
"""

from __future__ import annotations

import csv
import hashlib
import os
import shutil
import subprocess
import tarfile
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[3]
#: Debian package -> a file it installs (None: a program of that name)
FMUSIM_PACKAGES = {"gcc": None, "libxml2-dev": "/usr/include/libxml2/libxml/parser.h",
                   "zlib1g-dev": "/usr/include/zlib.h", "libminizip-dev": "/usr/include/minizip/unzip.h",
                   "libsundials-dev": "/usr/include/cvode/cvode.h"}
FMUCHECK_PACKAGES = {"gcc": None, "g++": None, "cmake": None, "make": None}
FMUSIM_TARBALL = "reference-fmus-0.0.39-fmusim.tar.gz"
#: communication points per run: short runs at each FMU's scenario step
POINTS = 50


def vendor() -> Path | None:
    for folder in filter(None, [os.environ.get("OBSFMU_VENDOR"), ROOT.parent / "shared" / "vendor",
                                ROOT.parent.parent / "shared" / "vendor"]):
        if (Path(folder) / "build-fmusim.sh").is_file():
            return Path(folder)
    return None


def missing(packages: dict) -> list[str]:
    return [name for name, header in packages.items()
            if (header is None and shutil.which(name) is None) or (header is not None and not Path(header).is_file())]


def cached_build(script: Path, sources: list[Path], binary: str, packages: dict, tag: str = "") -> Path:
    """``script OUT`` run once into the cache (keyed by the script and its sources); skips without them."""
    absent = missing(packages)
    if absent:
        pytest.skip(f"building {binary} needs the Debian packages {' '.join(absent)} (installed by .ci/run)")
    key = hashlib.sha256(b"".join(p.read_bytes() for p in [script, *sources]) + tag.encode()).hexdigest()[:16]
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "obsfmu" / "importers" / key
    if not (cache / binary).is_file():
        temporary = cache.with_name(key + ".partial")
        shutil.rmtree(temporary, ignore_errors=True)
        completed = subprocess.run([str(script), str(temporary)], capture_output=True, text=True, timeout=1800)
        assert completed.returncode == 0, completed.stdout[-3000:] + completed.stderr[-3000:]
        shutil.rmtree(cache, ignore_errors=True)
        temporary.rename(cache)
    return cache / binary


@pytest.fixture(scope="session")
def vendor_dir():
    folder = vendor()
    if folder is None:
        pytest.skip("the third-party importers' sources (../shared/vendor, or $OBSFMU_VENDOR) are not here")
    return folder


@pytest.fixture(scope="session")
def fmusim(vendor_dir):
    return cached_build(vendor_dir / "build-fmusim.sh", [vendor_dir / FMUSIM_TARBALL], "fmusim", FMUSIM_PACKAGES)


@pytest.fixture(scope="session")
def fmusim_fixed(vendor_dir, tmp_path_factory):
    """fmusim with its one FMU-state bug fixed (``FMIUtil_fixstate.c`` of the same tarball: ``&state``)."""
    work = tmp_path_factory.mktemp("fmusim_fixed")
    with tarfile.open(vendor_dir / FMUSIM_TARBALL) as archive:
        archive.extractall(work / "src", filter="data")
    folder = work / "src" / "reference-fmus-0.0.39" / "fmusim"
    shutil.copy(folder / "FMIUtil_fixstate.c", folder / "FMIUtil.c")
    with tarfile.open(work / FMUSIM_TARBALL, "w:gz") as archive:
        archive.add(work / "src" / "reference-fmus-0.0.39", arcname="reference-fmus-0.0.39")
    shutil.copy(vendor_dir / "build-fmusim.sh", work / "build-fmusim.sh")
    return cached_build(work / "build-fmusim.sh", [vendor_dir / FMUSIM_TARBALL], "fmusim", FMUSIM_PACKAGES,
                        tag="FMIUtil_fixstate.c")


@pytest.fixture(scope="session")
def fmucheck(vendor_dir):
    tarball = next(vendor_dir.glob("fmu-compliance-checker-*.tar.gz"))
    return cached_build(vendor_dir / "build-fmucheck.sh", [tarball], "fmuCheck.linux64", FMUCHECK_PACKAGES)


def run_tool(command, cwd) -> subprocess.CompletedProcess:
    """A third-party tool in an empty environment (the FMUs find their Python themselves)."""
    return subprocess.run(list(map(str, command)), cwd=cwd, env={}, capture_output=True, text=True, timeout=600)


def read_csv(path: Path) -> tuple[list[str], np.ndarray]:
    """Column names and values; an FMI 3.0 array is one column of space-separated elements (flattened)."""
    with open(path) as handle:
        rows = list(csv.reader(handle))
    return rows[0], np.array([[float(x) for field in row for x in field.split()] for row in rows[1:]])


def test_every_fmi2_fmu_passes_the_compliance_checker(fmucheck, every_fmu, tmp_path):
    failures = {}
    for model, (step, path) in sorted(every_fmu.items()):
        completed = run_tool([fmucheck, "-h", step, "-s", POINTS * step, "-o", tmp_path / f"{model}.csv", path],
                             tmp_path)
        report = completed.stdout + completed.stderr
        passed = "\t0 Error(s)" in report and "Simulation finished successfully" in report
        if completed.returncode != 0 or not passed:
            failures[model] = report[-1500:]
    assert not failures, failures
    assert len(every_fmu) == 20                 # README: "all 20 FMI 2.0"


GPEBO = ("gpebo_source", "gpebo_plant", "gpebo_observer")  #: discrete FMUs: they sample at k Ts at any step


def gpebo_paths(fixture, request) -> tuple[float, float, dict]:
    """The GPEBO FMUs and their scenario's stop time and step (what their DefaultExperiment declares)."""
    from obsfmu.fmus.scenarios import get
    scenario, fmus = get("discrete-gpebo"), request.getfixturevalue(fixture)
    return scenario.stop_time, scenario.step, {model: fmus[model][1] for model in GPEBO}


def test_fmucheck_with_its_defaults_runs_the_discrete_fmus(fmucheck, request, tmp_path):
    """fmuCheck 2.0.3 reads startTime and stopTime of the DefaultExperiment, not its stepSize: its step is the stop
    time over 500 points (``prepare_time_step_info`` in src/Common/fmuChecker.c), 0.08 s for the GPEBO FMUs of
    Ts = 1 s.  They refused it (issue 36: 2 of 20 FMUs failed fmuCheck's defaults); sampled at k Ts at any step,
    they run it, state held between the instants."""
    stop, step, paths = gpebo_paths("every_fmu", request)
    for model, path in paths.items():
        completed = run_tool([fmucheck, "-o", tmp_path / f"{model}.csv", path], tmp_path)
        report = completed.stdout + completed.stderr
        assert completed.returncode == 0 and "\t0 Error(s)" in report, report[-2000:]
        rows = read_csv(tmp_path / f"{model}.csv")[1]
        assert len(rows) >= 490 and abs(rows[-1, 0] - stop) < 0.1 and np.all(np.diff(rows[:, 0]) > 0)
        assert np.all(np.isfinite(rows))      # (fmuCheck's CSV skips a row now and then: 0.8 s is missing)


@pytest.mark.parametrize("fixture", ["every_fmu", "every_fmu3"])
def test_fmusim_without_options_runs_the_default_experiment(fmusim, request, fixture, tmp_path):
    """No --start-time, --stop-time, --output-interval: fmusim runs 0..40 s at 1 s, which the GPEBO FMUs accept
    (before they declared no DefaultExperiment: fmusim ran them at 1/500 of 1 s and they refused)."""
    stop, step, paths = gpebo_paths(fixture, request)
    for model, path in paths.items():
        out = tmp_path / f"{model}.csv"
        completed = run_tool([fmusim, "--interface-type", "cs", "--output-file", out, path], tmp_path)
        assert completed.returncode == 0, (model, (completed.stdout + completed.stderr)[-2000:])
        rows = read_csv(out)[1]
        np.testing.assert_allclose(rows[:, 0], np.arange(round(stop / step) + 1) * step, rtol=0, atol=1e-9)
        assert np.all(np.isfinite(rows))


def fmusim_run(fmusim, path, step, work, *options, stop=None):
    out = work / f"{Path(path).stem}.csv"
    completed = run_tool([fmusim, "--interface-type", "cs", "--stop-time", stop or POINTS * step,
                          "--output-interval", step, "--output-file", out, *options, path], work)
    return completed, out


@pytest.mark.parametrize("fixture", ["every_fmu", "every_fmu3"])
def test_every_fmu_runs_in_fmusim(fmusim, request, fixture, tmp_path):
    fmus = request.getfixturevalue(fixture)
    failures = {}
    for model, (step, path) in sorted(fmus.items()):
        completed, out = fmusim_run(fmusim, path, step, tmp_path)
        rows = read_csv(out)[1] if out.is_file() else np.empty((0, 0))
        if completed.returncode != 0 or len(rows) != POINTS + 1 or not np.all(np.isfinite(rows)):
            failures[model] = (completed.returncode, len(rows), (completed.stdout + completed.stderr)[-1500:])
    assert not failures, failures


def test_fmusim_0_0_39_freeing_a_state_with_the_state_itself_no_longer_crashes(fmusim, ship_fmus, tmp_path):
    step, state = 1e-3, tmp_path / "state.bin"
    completed, _ = fmusim_run(fmusim, ship_fmus["ship_plant"], step, tmp_path, "--final-fmu-state-file", state)
    assert completed.returncode > 0, (completed.returncode, completed.stdout[-2000:])  # fmusim's own error: no signal
    assert "given the FMU state itself instead of its address" in completed.stdout + completed.stderr
    assert state.stat().st_size > 0


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("scenario, model", [("ship", "ship_plant"), ("ltv-ls", "ltv_ls_plant")])
def test_a_state_saved_by_fmusim_restores_the_run(fmusim_fixed, build_dir, tmp_path, version, scenario, model):
    """0 -> t1 saving the state, then t1 -> t2 from that state file = 0 -> t2 in one run, at every point
    (the LTI ship plant, and paper 001's nonlinear LTV plant with its RK4 sub-steps)."""
    from obsfmu.fmus.scenarios import ensure_fmus, get
    path = ensure_fmus(get(scenario), build_dir, fmi_version=version)[model]
    step, half = 1e-3, POINTS // 2 * 1e-3
    state = tmp_path / "state.bin"
    (whole := tmp_path / "whole").mkdir()
    (first := tmp_path / "first").mkdir()
    (second := tmp_path / "second").mkdir()
    done, whole_csv = fmusim_run(fmusim_fixed, path, step, whole)
    saved, _ = fmusim_run(fmusim_fixed, path, step, first, "--final-fmu-state-file", state, stop=half)
    restored, rest_csv = fmusim_run(fmusim_fixed, path, step, second, "--initial-fmu-state-file", state,
                                    "--start-time", half)
    for completed in (done, saved, restored):
        assert completed.returncode == 0, completed.stdout[-2000:] + completed.stderr[-2000:]
    (names, expected), (names_rest, rest) = read_csv(whole_csv), read_csv(rest_csv)
    assert names == names_rest and len(rest) == POINTS // 2 + 1
    np.testing.assert_allclose(rest[:, 0], expected[POINTS // 2:, 0], rtol=0, atol=1e-12)
    # fmusim's grid of the second run is t1 + k h, not (n + k) h: steps differ in the last bit (measured 2.4e-16)
    np.testing.assert_allclose(rest[:, 1:], expected[POINTS // 2:, 1:], rtol=1e-13, atol=0)


@pytest.mark.parametrize("version", [2, 3])
def test_fmusim_agrees_with_fmpy(fmusim, build_dir, tmp_path, version):
    """The ship plant alone (its input at its start value): fmusim and fmpy.simulate_fmu, point by point."""
    from fmpy import simulate_fmu

    from obsfmu.fmus.scenarios import ensure_fmus, get
    path = ensure_fmus(get("ship"), build_dir, fmi_version=version)["ship_plant"]
    step = 1e-3
    completed, out = fmusim_run(fmusim, path, step, tmp_path)
    assert completed.returncode == 0, completed.stdout[-2000:]
    names, theirs = read_csv(out)
    ours = simulate_fmu(str(path), stop_time=POINTS * step, step_size=step, output_interval=step,
                        output=names[1:], fmi_type="CoSimulation")
    assert len(ours) == len(theirs)
    np.testing.assert_allclose(theirs[:, 0], ours["time"], rtol=0, atol=1e-12)
    ours_values = np.column_stack([np.asarray(ours[name]).reshape(len(ours), -1) for name in names[1:]])
    assert ours_values.shape == theirs[:, 1:].shape
    np.testing.assert_allclose(theirs[:, 1:], ours_values, rtol=1e-12, atol=1e-15)  # measured: 2.7e-16 relative
