"""Faults of the environment an FMU or a command runs in (issue 29, findings 8 and 10).

* an FMU run by a Python with another numpy version than it was built and tested with says so in its log, once
  per process and FMU, at Warning level (``fmus.runtime.slave.versions``; scipy is not compared: no FMU imports it
  at run time);
* a cache on a read-only file system (``OBSFMU_CACHE``, ``HOME``): every command still works, on a private
  temporary cache, said once on stderr naming the folder and the variable (``fmus.caches``).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from faults_support import WARNING, Probe

ROOT = Path(__file__).resolve().parents[2]


def _recorded_as(fmu: Path, copy: Path, built_with: dict) -> Path:
    """A copy of ``fmu`` whose build record names other numpy / scipy versions."""
    with zipfile.ZipFile(fmu) as source, zipfile.ZipFile(copy, "w", zipfile.ZIP_DEFLATED) as target:
        for entry in source.infolist():
            data = source.read(entry)
            if entry.filename == "resources/build_info.json":
                data = json.dumps({**json.loads(data), "built_with": built_with}).encode()
            target.writestr(entry, data)
    return copy


def _version_lines(probe: Probe) -> list[tuple[int, str]]:
    return [(status, text) for status, text in probe.log if "was built and tested with" in text]


def test_an_fmu_of_another_numpy_version_says_so_once(ship_fmus, tmp_path):
    """Before: an FMU built on numpy 2.4 ran on numpy 1.26 with outputs 1e-6 apart and no word."""
    from obsfmu.fmus.runtime.slave.versions import running
    fmu = ship_fmus["ship_plant"]
    with zipfile.ZipFile(fmu) as archive:
        assert json.loads(archive.read("resources/build_info.json"))["built_with"] == running()
    same = Probe(fmu, name="same")
    assert _version_lines(same) == [], same.messages()
    same.free()
    now = running()
    other = _recorded_as(fmu, tmp_path / "ship_plant.fmu", {"numpy": "1.26.4", "scipy": "1.11.4"})
    first, second = Probe(other, name="first"), Probe(other, name="second")
    assert _version_lines(first) == [(WARNING, f"ship_plant was built and tested with numpy 1.26.4; "
                                               f"this Python runs numpy {now['numpy']}: "
                                               f"results may differ in the last digits")], first.messages()
    assert _version_lines(second) == [], "once per process and FMU"
    assert first.step(0.01) == 0 and second.step(0.01) == 0
    first.free()
    second.free()


def test_scipy_is_not_compared_no_fmu_imports_it_at_run_time(ship_fmus, tmp_path):
    """Every standalone FMU in a process without Python warned "... this Python runs numpy 2.4.6, scipy none"
    (issue 35): an FMU whose record differs in scipy alone says nothing."""
    from obsfmu.fmus.runtime.slave.versions import running
    other = _recorded_as(ship_fmus["ship_plant"], tmp_path / "ship_plant.fmu",
                         {"numpy": running()["numpy"], "scipy": "0.1"})
    probe = Probe(other, name="scipy")
    assert _version_lines(probe) == [], probe.messages()
    probe.free()


def _read_only(folder: Path, command: str, **env) -> subprocess.CompletedProcess:
    """``command`` (a shell line) with ``folder`` bind-mounted read-only in a mount namespace of its own."""
    script = f"mount --bind {folder} {folder} && mount -o remount,bind,ro {folder} && {command}"
    return subprocess.run(["unshare", "-m", "sh", "-c", script], capture_output=True, text=True, cwd=ROOT,
                          env={key: value for key, value in {**os.environ, **env}.items() if value is not None},
                          timeout=600)


@pytest.fixture
def read_only_folder(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    if not shutil.which("unshare"):
        pytest.skip("unshare not installed: no read-only mount to test with")
    probe = _read_only(folder, f"touch {folder}/x")
    if "Read-only file system" not in probe.stderr:
        pytest.skip(f"no read-only bind mount in a mount namespace here (needs root): {probe.stderr.strip()}")
    return folder


@pytest.mark.parametrize("variable", ["OBSFMU_CACHE", "HOME"])
def test_run_on_a_read_only_cache_falls_back_to_a_private_temporary_one(build_dir, read_only_folder, variable):
    """Before: ``obsfmu: error: <dir>: Read-only file system``, exit 2, the variable not named.  Now the run
    works, one note on stderr names the folder, the variable and the stand-in, removed at exit."""
    from obsfmu.fmus.scenarios import ensure_fmus, get
    ensure_fmus(get("ship"), build_dir)
    env = {variable: str(read_only_folder)}
    if variable == "HOME":
        env.update(XDG_CACHE_HOME=None, OBSFMU_CACHE=None)
    command = f"{sys.executable} -m obsfmu run ship --build-dir {build_dir} --stop-time 0.01"
    done = _read_only(read_only_folder, command, **env)
    assert done.returncode == 0, done.stderr
    notes = [line for line in done.stderr.splitlines() if line.startswith("obsfmu: note: the cache")]
    assert notes and len(notes) == len(set(notes)) and len(notes) == len(done.stderr.strip().splitlines()), \
        done.stderr
    assert f"the cache {read_only_folder}" in notes[0] and "Read-only file system" in notes[0]
    assert f"chosen by {'OBSFMU_CACHE' if variable == 'OBSFMU_CACHE' else 'HOME (or '}" in notes[0]
    stand_in = Path(notes[0].split("this process caches in ")[1].split(" instead")[0])
    assert not stand_in.parent.exists(), "the private cache is removed when the process ends"
    assert "ship: " in done.stdout


def test_a_slave_that_cannot_be_made_again_at_reset_is_logged_with_its_exception(ship_fmus, tmp_path):
    """Sweeps met ``fmi2Reset: error: unknown error``: the bridge cleared the exception of the failed
    re-creation before logging it.  Now fmi2Reset is fmi2Error naming the exception; the host goes on."""
    copy = tmp_path / "plant.fmu"
    shutil.copy(ship_fmus["ship_plant"], copy)
    probe = Probe(copy, name="reset")
    resources = Path(probe.slave.unzipDirectory) / "resources"
    (resources / "ship_plant.json").unlink()            # its definition: what a fresh slave reads first
    before = len(probe.log)
    assert probe.call(probe.slave.fmi2Reset, probe.slave.component) == 3       # fmi2Error
    message = probe.messages(before)
    assert "fmi2Reset: FileNotFoundError:" in message and "ship_plant.json" in message, message
    assert "unknown error" not in message
    probe.free()
