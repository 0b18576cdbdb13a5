"""``pip install .`` (not editable) from a clean clone gives a working ``obsfmu build`` and ``obsfmu run``.

Kept cheap: the temporary venv sees this environment's packages through a ``.pth`` line (numpy,
scipy, fmpy, pip, setuptools, ...) -- but not the editable obsfmu, whose import hook lives in a
``.pth`` file that is not processed from there -- and the wheel is built offline
(``--no-build-isolation --no-deps``).  The native binaries are compiled into an empty cache from
the installed C sources.
"""

import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

from obsfmu.fmus.builder import PROJECT_ROOT


def clean_clone(destination: Path) -> Path:
    """The project's tracked files (what ``git clone`` gives), or its sources when not in git."""
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=PROJECT_ROOT, capture_output=True)
    files = [f for f in listed.stdout.decode().split("\0") if f] if listed.returncode == 0 else []
    if not files:
        files = ["pyproject.toml", "setup.cfg", "setup.py", "README.md"] + [
            str(p.relative_to(PROJECT_ROOT)) for package in ("obsfmu", "fmus", "observers", "plants")
            for p in (PROJECT_ROOT / package).rglob("*") if p.is_file() and "__pycache__" not in p.parts]
    for name in files:
        if (PROJECT_ROOT / name).is_file():
            (destination / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(PROJECT_ROOT / name, destination / name)
    return destination


def test_pip_install_then_build_and_run_from_elsewhere(tmp_path):
    clone = clean_clone(tmp_path / "clone")
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    site = subprocess.run([str(venv / "bin" / "python"), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          capture_output=True, text=True, check=True).stdout.strip()
    Path(site, "test_environment.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    environment = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "cache"), "PIP_NO_INDEX": "1"}
    environment.pop("PYTHONPATH", None)

    def command(*args, cwd):
        completed = subprocess.run([str(a) for a in args], cwd=cwd, env=environment, capture_output=True, text=True,
                                   timeout=900)
        assert completed.returncode == 0, completed.stdout[-3000:] + completed.stderr[-3000:]
        return completed.stdout

    command(venv / "bin" / "python", "-m", "pip", "install", "--no-deps", "--no-build-isolation", ".", cwd=clone)
    assert not (clone / "build").exists()  # setuptools' output went to .setuptools-build (setup.cfg)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    location = command(venv / "bin" / "python", "-c", "import obsfmu.fmus.native as n; print(n.__file__)", cwd=elsewhere)
    assert location.startswith(site), location  # the installed copy, not this checkout
    installed = sorted(p.name for p in Path(site).iterdir() if p.is_dir() and not p.name.endswith("-info"))
    assert installed == ["obsfmu"], installed     # issue 38: no collision-prone top-level package (fmus, plants, ...)

    built = command(venv / "bin" / "obsfmu", "build", cwd=elsewhere)
    # issue 38: an installed obsfmu builds into its cache ($XDG_CACHE_HOME/obsfmu/build), not the working directory
    assert "INVALID" not in built and (tmp_path / "cache" / "obsfmu" / "build" / "ship_observer.fmu").is_file()
    assert not (elsewhere / "build").exists()
    assert list((tmp_path / "cache" / "obsfmu" / "native").glob("obsfmu_loader-*"))  # compiled from the install
    ran = command(venv / "bin" / "obsfmu", "run", "ship", "--stop-time", "0.05", cwd=elsewhere)
    assert "ship:" in ran
