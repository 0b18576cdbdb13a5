"""``obsfmu list``, ``--help`` and ``--version`` import only what they need (issue 39): not numpy, fmpy,
tqdm or the master, which cost ~1 s of start-up (the time itself is measured in
benchmarks/cosimulation_costs.py --only startup, not here).  The scenario list they print comes from the
system files alone (:mod:`fmus.catalogue`) and must say what the registry says."""

from __future__ import annotations

import subprocess
import sys
from importlib.metadata import version

import pytest

from obsfmu.fmus.catalogue import entries

HEAVY = ("numpy", "fmpy", "tqdm", "scipy", "obsfmu.fmus.master", "obsfmu.fmus.scenarios")

PROBE = """
import contextlib, io, sys
from obsfmu.fmus.cli.main import main
with contextlib.redirect_stdout(io.StringIO()) as out:
    codes = [main(argv) for argv in [{argvs}]]
print(codes, out.getvalue().count("defaults: stop"))
print(",".join(m for m in {heavy} if m in sys.modules))
"""


@pytest.mark.parametrize("argvs", [[["list"]], [["--help"]], [["--version"]], [["list", "--help"]]])
def test_the_light_commands_do_not_import_the_heavy_modules(argvs):
    probe = PROBE.format(argvs=", ".join(map(repr, argvs)), heavy=HEAVY)
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    codes, imported = done.stdout.splitlines()
    assert codes.split("]")[0] == "[" + ", ".join("0" for _ in argvs)
    if argvs == [["list"]]:
        assert codes.split("] ")[1] == str(len(entries()))       # every scenario listed
    assert imported == "", f"{argvs} imported {imported}"


def test_a_heavy_command_still_reports_its_errors_in_one_line():
    """The errors are caught by the modules that define them only once imported: a bad scenario name is
    still one line and exit 2."""
    done = subprocess.run([sys.executable, "-m", "obsfmu", "run", "no-such-scenario"], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [done.stderr.strip()]
    assert "unknown scenario 'no-such-scenario'" in done.stderr


def test_version_from_the_command_line():
    done = subprocess.run([sys.executable, "-m", "obsfmu", "--version"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0
    assert done.stdout.strip() == f"obsfmu {version('obsfmu')}"


def test_the_catalogue_says_what_the_registry_says():
    from obsfmu.fmus.scenarios import SCENARIOS

    fields = ("description", "stop_time", "step", "order", "coupling", "time_unit")
    assert list(entries()) == list(SCENARIOS)
    for name, entry in entries().items():
        assert {f: getattr(entry, f) for f in fields} == {f: getattr(SCENARIOS[name], f) for f in fields}, name
