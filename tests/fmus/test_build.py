"""``obsfmu build``: every distinct FMU built once, validated once, by a validation equal to fmpy's."""

from __future__ import annotations

import signal
import tempfile
import zipfile
from pathlib import Path

import pytest
from fmpy.model_description import ModelDescription, ScalarVariable
from fmpy.validation import _validate_variable_names
from fmpy.validation import validate_fmu as fmpy_validate

import obsfmu.fmus.scenarios as scenarios
from obsfmu.fmus.cli import main as cli, runs
from obsfmu.fmus.master import SimulationError
from obsfmu.fmus.validation import plain_name, validate_fmu

NAMES = ["x", "x_hat[1]", "A[12,3]", "a.b[1].c", "_", "der(x)", "der(x[1],2)", "x[01]",
         "1x", "x[]", "x[1,]", "x [1]", "der(x", "a..b", "x[1][2]", "x[-1]", "'quoted name'", "é"]


@pytest.mark.parametrize("name", NAMES)
def test_the_fast_name_check_accepts_only_what_fmpys_grammar_accepts(name):
    description = ModelDescription(fmiVersion="2.0", variableNamingConvention="structured",
                                   modelVariables=[ScalarVariable(name=name, sourceline=1)])
    grammar_accepts = _validate_variable_names(description) == []
    assert not plain_name(name) or grammar_accepts, name        # the regular subset is inside the grammar
    assert plain_name(name) == (name in NAMES[:8])               # and covers every name the project writes


def _with_renamed_variable(source: Path, target: Path, old: str, new: str) -> Path:
    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(target, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = data.replace(f'name="{old}"'.encode(), f'name="{new}"'.encode())
            zout.writestr(item, data)
    return target


def test_validation_reports_exactly_what_fmpy_reports(ship_fmus, tmp_path):
    observer = ship_fmus["ship_observer"]
    for path in ship_fmus.values():
        assert validate_fmu(path) == fmpy_validate(str(path)) == [], path
    renamed = _with_renamed_variable(observer, tmp_path / "renamed.fmu", "x_hat[1]", "x hat[1]")
    duplicate = _with_renamed_variable(observer, tmp_path / "duplicate.fmu", "x_hat[1]", "x_hat[2]")
    for broken in (renamed, duplicate):
        problems = validate_fmu(broken)
        assert problems and problems == fmpy_validate(str(broken)), broken


def test_build_builds_and_validates_each_distinct_fmu_once(monkeypatch, tmp_path, capsys):
    built, validated = [], []

    def fake_build(definition, out_dir, extra_modules=(), fmi_version=2, standalone=False, platforms=None):
        built.append(definition.model_name)
        path = Path(out_dir) / f"{definition.model_name}.fmu"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(b"")
        return path

    monkeypatch.setattr(scenarios, "build_fmu", fake_build)
    monkeypatch.setattr(scenarios, "_damage", lambda path, platforms=None: None)   # the fakes are empty files
    monkeypatch.setattr(runs, "validate", lambda path: validated.append(Path(path).stem) or [])
    assert cli.main(["build", "--out", str(tmp_path)]) == 0
    distinct = {item.model_name if not isinstance(item, tuple) else item[0].model_name
                for scenario in scenarios.SCENARIOS.values() for item in scenario.definitions()}
    assert sorted(built) == sorted(distinct) == sorted(validated)
    assert {"ltv_ls_plant", "ltv_ls_bounded_plant"} <= set(built)    # each system file its own FMUs
    assert capsys.readouterr().out.count("(valid)") == len(distinct)


def test_two_scenarios_defining_one_fmu_differently_are_refused(monkeypatch, tmp_path):
    monkeypatch.setattr(scenarios, "build_fmu", lambda *args, **kwargs: pytest.fail("built"))
    ship = scenarios.get("ship")
    definitions = ship.definitions()
    changed = [d for d in ship.definitions()]
    changed[0].description = "another description"
    first = scenarios.Scenario("first", "", lambda: definitions, [], [], 1.0, 0.1)
    second = scenarios.Scenario("second", "", lambda: changed, [], [], 1.0, 0.1)
    with pytest.raises(SimulationError, match=f"{changed[0].model_name}: scenarios 'first' and 'second' "
                                              "define this FMU differently"):
        scenarios.ensure_all([first, second], tmp_path, force=True)


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGHUP], ids=lambda s: s.name)
def test_a_stop_signal_during_a_build_is_taken_once_the_fmu_is_complete(monkeypatch, tmp_path, signum):
    """The signal comes while the archive is written (a cut there leaves zipfile unable to close); it is raised
    when the FMU is complete, and nothing else is left: no partial archive, no temporary build folder."""
    from obsfmu.fmus import builder
    from obsfmu.fmus.cli import stopping
    from obsfmu.fmus.runtime.kinds.signals import source_definition

    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    write = zipfile.ZipFile.writestr
    signalled = []

    def writestr(archive, name, data, *args, **kwargs):
        if not signalled:
            signalled.append(name)
            signal.raise_signal(signum)
        return write(archive, name, data, *args, **kwargs)

    monkeypatch.setattr(zipfile.ZipFile, "writestr", writestr)
    previous = stopping.install_handlers(stopping.raise_terminated, ignored_too=())
    try:
        with pytest.raises(stopping.Terminated) as stopped:
            builder.build_fmu(source_definition("held_source"), tmp_path / "out")
    finally:
        stopping.restore_handlers(previous)
    assert stopping.interrupted_status(stopped.value) == 128 + signum and signalled
    assert validate_fmu(tmp_path / "out" / "held_source.fmu") == []
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [".held_source.fmu.built", "held_source.fmu"]
    assert not list(scratch.iterdir())                 # the FMU and its build record (fmus.builder.record_path)


def test_a_second_build_of_every_scenario_fmu_builds_nothing(every_fmu, build_dir):
    """Issue 37: `obsfmu all` rebuilt every FMU on every run.  Every FMU is current (judged by content),
    so building them all again rewrites no file; --rebuild does."""
    before = {path: path.stat().st_mtime_ns for _, path in every_fmu.values()}
    again = runs.build_all(build_dir)
    assert set(again) == set(before)
    assert {path: path.stat().st_mtime_ns for path in before} == before


def test_a_full_disk_in_the_build_folder_is_one_line_naming_the_fmu(tmp_path, monkeypatch, capsys):
    """Issue 37.8: ``--build-dir`` on a full disk ended in ``obsfmu: error: No space left on device`` naming no
    path (the zip's write carries no file name).  Now the FMU's path, exit 2, and no partial file left."""
    import errno
    import zipfile

    from obsfmu.fmus.cli import main as cli

    def full(self, *args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(zipfile.ZipFile, "writestr", full)
    build = tmp_path / "build"
    assert cli.main(["run", "ship", "--build-dir", str(build), "--stop-time", "0.01"]) == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith("obsfmu: error: ") and "\n" not in error, error
    assert error.endswith(".fmu: No space left on device") and str(build) in error, error
    assert not [p.name for p in build.iterdir() if p.name.startswith(".")]
