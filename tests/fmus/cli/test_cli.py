"""The command line never shows a traceback for a user mistake (issue 13, item 6) and documents itself (16.4).

Every bad input of the issue's list gets one line on stderr naming the argument or field, and
exit code 2 -- before anything is simulated.  Run in-process through ``fmus.cli.main``.
"""

from __future__ import annotations

import argparse
import io
import os
import shutil
import signal
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description

from obsfmu.fmus.cli import main as cli
from obsfmu.fmus.cli import commands
from obsfmu.fmus.cli.commands import run_into
from obsfmu.fmus.cli.stopping import StopRequest
from obsfmu.fmus.result import Result
from obsfmu.fmus.scenarios import SCENARIOS, ensure_fmus, get


def _unwritable_directory(tmp_path):
    """A directory this process cannot create files in (chmod for normal users; /sys for root)."""
    candidate = tmp_path / "read-only"
    candidate.mkdir()
    candidate.chmod(0o555)
    for directory in (candidate, "/sys"):
        try:
            with tempfile.TemporaryFile(dir=directory):
                continue
        except OSError:
            return str(directory)
    pytest.skip("no directory here refuses new files")


@pytest.fixture(scope="module")
def ship_build(build_dir):
    ensure_fmus(get("ship"), build_dir)
    return str(build_dir)


@pytest.fixture
def no_simulation(monkeypatch):
    """Fail the test if an FMU is instantiated: the error must come before the simulation."""
    import obsfmu.fmus.scenarios as scenarios_module

    def refuse(*args, **kwargs):
        raise AssertionError("the simulation started although the command line was bad")
    monkeypatch.setattr(scenarios_module, "Session", refuse)


def _configs(tmp_path):
    (tmp_path / "empty.toml").write_text("")
    (tmp_path / "booleans.toml").write_text(
        'name = "b"\n[plant]\nA = [[true, 1], [0, 0]]\nC = [[1, 0]]\n[observer]\nt_settle = 1.0\n')
    (tmp_path / "a-directory.toml").mkdir()
    (tmp_path / "a-file").write_text("x")


BAD = {  # id: (argv with {B} = build dir, {T} = tmp dir, {RO} = unwritable dir; expected text on stderr)
    "output-interval 0": (["run", "ship", "--output-interval", "0"], "argument --output-interval: must be a positive"),
    "output-interval -1": (["run", "ship", "--output-interval", "-1"], "argument --output-interval: must be a positive"),
    "stop-time inf": (["run", "ship", "--stop-time", "inf"], "argument --stop-time: must be a positive finite number"),
    "stop-time nan": (["run", "ship", "--stop-time", "nan"], "argument --stop-time: must be a positive finite number"),
    "stop-time words": (["run", "ship", "--stop-time", "5 parsec"], "argument --stop-time: '5 parsec' is not a time"),
    "step 0": (["run", "ship", "--step", "0"], "argument --step: must be a positive finite number"),
    "step > stop time": (["run", "ship", "--step", "2", "--stop-time", "1"],
                         "--step 2 s: longer than the run (--stop-time 1 s); ship's default step is 2e-05 s"),
    "tol -1": (["run", "ship", "--tol", "-1"], "argument --tol: must be a positive finite number"),
    "export step 0": (["export", "ship", "--format", "ssp", "--out", "{T}/x", "--step", "0"],
                      "argument --step: must be a positive finite number"),
    "export set nan": (["export", "ship", "--format", "ssp", "--out", "{T}/x", "--set", "plant.x0[1]=nan"],
                       "--set 'plant.x0[1]=nan': the value must be a finite number"),
    "run set inf": (["run", "ship", "--set", "plant.x0[1]=inf"], "--set 'plant.x0[1]=inf': the value must be a finite"),
    "run set nan": (["run", "ship", "--set", "plant.x0[1]=nan"], "--set 'plant.x0[1]=nan': the value must be a finite"),
    "set above max": (["run", "ship", "--set", "observer.u_interpolation=7"],
                      "--set observer.u_interpolation=7: above the maximum 2 declared by the FMU"),
    "set below min": (["run", "ship", "--set", "observer.u_interpolation=-1"],
                      "--set observer.u_interpolation=-1: below the minimum 0"),
    "set integer": (["run", "ship", "--set", "observer.u_interpolation=1.5"],
                    "--set observer.u_interpolation=1.5: Integer variable, expected a whole number"),
    "set output": (["run", "ship", "--set", "observer.x_hat[1]=1"],
                   "--set observer.x_hat[1]: is an output of observer and cannot be set"),
    "set connected input": (["run", "ship", "--set", "observer.y=1"], "--set observer.y: is a connected input"),
    "export set output": (["export", "ship", "--format", "osp", "--out", "{T}/x", "--set", "plant.y=1"],
                          "--set plant.y: is an output of plant"),
    "config boolean": (["build", "--config", "{T}/booleans.toml", "--out", "{T}/b"],
                       "plant.A: entry (1, 1) is true, expected a number"),
    "config empty": (["build", "--config", "{T}/empty.toml", "--out", "{T}/b"], "the file is empty"),
    "config directory": (["build", "--config", "{T}/a-directory.toml", "--out", "{T}/b"],
                         "a-directory.toml: is a directory, expected a TOML file"),
    "plot directory": (["run", "ship", "--plot", "{T}"], "--plot {T}: is a directory, expected a file name"),
    "plot format": (["run", "ship", "--plot", "{T}/figure.jpg"], "expected a file name ending in .png or .svg"),
    "csv directory": (["run", "ship", "--csv", "{T}"], "--csv {T}: is a directory, expected a file name"),
    "csv missing directory": (["run", "ship", "--csv", "{T}/missing/out.csv"], "directory {T}/missing does not exist"),
    "csv read-only directory": (["run", "ship", "--csv", "{RO}/out.csv"], "--csv {RO}/out.csv: cannot write in"),
    "build-dir a file": (["run", "ship", "--build-dir", "{T}/a-file"], "--build-dir {T}/a-file: is a file"),
    "build out a file": (["build", "--out", "{T}/a-file"], "--out {T}/a-file: is a file, expected a directory"),
    "build out read-only": (["build", "--out", "{RO}/sub"], "--out {RO}/sub: cannot create the directory"),
    "all out a file": (["all", "--out", "{T}/a-file"], "--out {T}/a-file: is a file, expected a directory"),
    "all out read-only": (["all", "--out", "{RO}/sub"], "--out {RO}/sub: cannot create the directory"),
    "export out read-only": (["export", "ship", "--format", "osp", "--out", "{RO}/sub"],
                             "--out {RO}/sub: cannot create the directory"),
    "all build-dir a file": (["all", "--build-dir", "{T}/a-file", "--out", "{T}/r"], "--build-dir {T}/a-file: is a file"),
    "all jobs 0": (["all", "--jobs", "0", "--out", "{T}/r"], "argument --jobs: must be at least 1, got 0"),
    "all jobs words": (["all", "--jobs", "two", "--out", "{T}/r"], "argument --jobs: 'two' is not an integer"),
    "export out a file": (["export", "ship", "--format", "ssp", "--out", "{T}/a-file"], "--out {T}/a-file: is a file"),
    "report out a file": (["report", "--out", "{T}/a-file"], "--out {T}/a-file: is a file, expected a directory"),
    "report jobs 0": (["report", "--jobs", "0", "--out", "{T}/r"], "argument --jobs: must be at least 1, got 0"),
    "unknown scenario": (["run", "nonesuch"], "unknown scenario 'nonesuch'; available: discrete-gpebo"),
    "unknown format": (["export", "ship", "--format", "fmi", "--out", "{T}/x"], "argument --format: invalid choice"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_bad_input_is_one_line_naming_it_and_exit_code_2(case, ship_build, tmp_path, capsys, no_simulation):
    argv, expected = BAD[case]
    _configs(tmp_path)
    values = {"T": str(tmp_path), "B": ship_build}
    if any("{RO}" in a for a in argv):
        values["RO"] = _unwritable_directory(tmp_path)
    argv = [a.format(**values) for a in argv]
    if "--build-dir" not in argv and argv[0] in ("run", "export"):
        argv += ["--build-dir", ship_build]
    assert cli.main(argv) == 2
    captured = capsys.readouterr()
    assert expected.format(**values) in captured.err
    assert len(captured.err.strip().splitlines()) == 1, captured.err
    assert "Traceback" not in captured.err + captured.out


def test_a_bad_parameter_reported_by_the_fmu_is_printed_once(ship_build, capsys):
    """``N[1] = 0`` passes the declared range but makes A - N C unstable: the FMU refuses it."""
    assert cli.main(["run", "ship", "--build-dir", ship_build, "--stop-time", "0.01", "--set", "observer.N[1]=0"]) == 2
    err = capsys.readouterr().err
    # the FMU refuses the set during initialization (the first call that needs the block)
    assert len(err.strip().splitlines()) == 1 and err.startswith("obsfmu: error: observer: ")
    assert "N: not Hurwitz" in err


def test_nonsense_values_are_not_written_to_an_export(ship_build, tmp_path):
    assert cli.main(["export", "ship", "--format", "ssp", "--out", str(tmp_path), "--build-dir", ship_build,
                     "--set", "plant.x0[1]=nan", "--step", "0"]) == 2
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("damage", ["modelDescription", "binary", "zip"])
def test_a_damaged_cached_fmu_is_rebuilt(ship_build, tmp_path, capsys, damage):
    build = tmp_path / "build"
    shutil.copytree(ship_build, build)
    fmu = build / "ship_observer.fmu"
    with zipfile.ZipFile(fmu) as archive:
        entries = {name: archive.read(name) for name in archive.namelist()}
    if damage == "modelDescription":
        entries["modelDescription.xml"] = entries["modelDescription.xml"][:200]
    elif damage == "binary":
        entries = {name: data for name, data in entries.items() if not name.startswith("binaries/")}
    if damage == "zip":
        fmu.write_bytes(fmu.read_bytes()[:1000])
    else:
        with zipfile.ZipFile(fmu, "w") as archive:
            for name, data in entries.items():
                archive.writestr(name, data)
    assert cli.main(["run", "ship", "--build-dir", str(build), "--stop-time", "0.01", "--step", "1e-3"]) == 0
    captured = capsys.readouterr()
    # judged by content: the FMU is not the file its build recorded (fmus.builder.why_not_current)
    assert f"{fmu}: edited since it was built" in captured.err and "rebuilding it" in captured.err
    assert "Traceback" not in captured.err
    assert read_model_description(str(fmu)).modelName == "ship_observer"


# ----------------------------------------------------------------------------- help (issue 16, item 4)
def _subparsers(parser):
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))


def test_every_subcommand_and_option_is_documented():
    subparsers = _subparsers(cli.parser())
    documented = {choice.dest: choice.help for choice in subparsers._choices_actions}
    assert set(documented) >= {"build", "list", "run", "export", "all", "report"}
    assert all(documented.values()), documented
    for name, sub in subparsers.choices.items():
        for action in sub._actions:
            if not isinstance(action, argparse._HelpAction):
                assert action.help, f"obsfmu {name} {action.option_strings or action.dest}: no help"


@pytest.mark.parametrize("command", ["run", "export"])
def test_help_lists_every_scenario_on_one_line(command, capsys):
    assert cli.main([command, "--help"]) == 0
    out = capsys.readouterr().out
    for name, scenario in SCENARIOS.items():
        lines = [line for line in out.splitlines() if line.split()[:1] == [name]]
        assert len(lines) == 1 and scenario.description in lines[0] and f"[{scenario.time_unit}]" in lines[0]


def test_a_subcommand_registers_itself_with_one_call(capsys):
    calls = []

    def configure(parser):
        parser.add_argument("--count", type=int, default=1, help="how many")

    cli.register("hello-test", "say hello (test)", configure, lambda args: calls.append(args.count) or 7)
    try:
        assert cli.main(["hello-test", "--count", "3"]) == 7 and calls == [3]
        assert cli.main(["--help"]) == 0 and "say hello (test)" in capsys.readouterr().out
        with pytest.raises(ValueError, match="registered twice"):
            cli.register("hello-test", "again", configure, lambda args: 0)
    finally:
        cli.SUBCOMMANDS.pop("hello-test")


# ----------------------------------------------------------------------------- a signal dropped on the way
class _DroppedUnclosed(io.RawIOBase):
    """A file left to its finalizer (as fmpy leaves the zip member it reads modelDescription.xml from): the
    signal comes while the finalizer closes it, and io's finalizer clears any exception ``close()`` raises."""

    def __init__(self, signum):
        super().__init__()
        self.signum = signum

    def close(self):
        signal.raise_signal(self.signum)        # the handler runs here: its Terminated is dropped
        super().close()


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP], ids=lambda s: s.name)
def test_a_signal_swallowed_outside_a_run_still_stops_the_command_before_its_run(signum, capsys):
    done = []

    def command(args):
        _DroppedUnclosed(signum)                # created and dropped at once
        done.append("went on")                  # nothing was raised here
        with StopRequest():
            done.append("ran")
        return 0

    cli.register("swallowed-test", "a signal swallowed (test)", lambda parser: None, command)
    try:
        assert cli.main(["swallowed-test"]) == 128 + signum and done == ["went on"]
        assert f"obsfmu: interrupted ({signum.name})" in capsys.readouterr().err
        assert cli.main(["list"]) == 0              # reported once: the next command starts afresh
    finally:
        cli.SUBCOMMANDS.pop("swallowed-test")


def test_a_stop_asked_after_the_last_run_writes_no_report_and_exits_with_the_signal(tmp_path, monkeypatch):
    from obsfmu.fmus import report
    monkeypatch.setattr(commands, "run_into", lambda out, build_dir, names, stop, jobs: stop._handle(signal.SIGTERM,
                                                                                                     None) or 0)
    monkeypatch.setattr(report, "write_report", lambda *a: pytest.fail("report written after a stop"))
    assert commands.run_and_report(tmp_path, tmp_path, ["ship"]) == 128 + signal.SIGTERM


# ----------------------------------------------------------------------------- time units (issue 16, item 2)
def test_times_are_in_the_scenarios_unit_unless_one_is_given(build_dir, tmp_path, capsys):
    """The chemostat runs in hours: 90min and 36s are 1.5 h and 0.01 h."""
    csv, figure = tmp_path / "chemostat.csv", tmp_path / "chemostat.png"
    assert cli.main(["run", "state-affine-chemostat", "--build-dir", str(build_dir), "--stop-time", "90min",
                     "--step", "36s", "--csv", str(csv), "--plot", str(figure)]) == 0
    out = capsys.readouterr().out
    assert "state-affine-chemostat: 150 steps to t = 1.5 h" in out
    assert "switched (nu < 0.98): not reached" in out and "inf" not in out
    result = Result.from_csv(csv)
    np.testing.assert_allclose(np.diff(result.time), 0.01, rtol=1e-9)
    assert result.time[-1] == pytest.approx(1.5)
    assert "time t [h]" in figure.with_suffix(".svg").read_text()


def test_the_steps_line_carries_the_time_unit(build_dir, capsys):
    assert cli.main(["run", "ship", "--build-dir", str(build_dir), "--stop-time", "0.05", "--step", "1e-3"]) == 0
    assert "ship: 50 steps to t = 0.05 s" in capsys.readouterr().out


def test_output_paths_are_checked_before_anything_is_built(tmp_path, monkeypatch, capsys):
    import obsfmu.fmus.scenarios as scenarios_module
    monkeypatch.setattr(scenarios_module, "ensure_fmus", lambda *a, **k: pytest.fail("built before the check"))
    assert cli.main(["run", "ship", "--build-dir", str(tmp_path / "b"), "--csv", str(tmp_path / "no" / "x.csv")]) == 2
    assert not (tmp_path / "b").exists() or not list((tmp_path / "b").iterdir())
    assert os.path.basename(str(tmp_path / "no")) in capsys.readouterr().err


# ----------------------------------------------------------------------------- obsfmu all --jobs N (issue 14)
#: two short runs; discrete-gpebo first in the printed order, ship (more steps) first in the pool
SHORT_ALL = {"discrete-gpebo": {"stop_time": 10.0}, "ship": {"stop_time": 0.05}}


def _run_all_short(out, build_dir, jobs, settings=SHORT_ALL) -> int:
    out.mkdir()
    with StopRequest() as stop:
        return run_into(out, build_dir, list(settings), stop, jobs, settings)


def _record(path):
    import json
    record = json.loads(path.read_text())
    assert record.pop("wall_time") > 0 and record.pop("written")
    return record


def test_all_in_two_worker_processes_writes_and_prints_what_one_process_does(build_dir, tmp_path, capsys):
    """``--jobs 2`` (spawned workers, longest first) against ``--jobs 1``: the same CSV, summary, figure and
    record (but its wall time) of every scenario, the summaries printed in the same order."""
    ensure_fmus(get("ship"), build_dir), ensure_fmus(get("discrete-gpebo"), build_dir)  # built before the pool
    printed = {}
    for jobs in (1, 2):
        assert _run_all_short(tmp_path / f"jobs{jobs}", build_dir, jobs) == 0
        captured = capsys.readouterr()
        printed[jobs] = captured.out.replace(f"jobs{jobs}", "DIR")
        assert "Traceback" not in captured.err
    assert printed[1] == printed[2]
    assert printed[2].index("== discrete-gpebo") < printed[2].index("== ship") and "max |co-simulation" in printed[2]
    one, two = tmp_path / "jobs1", tmp_path / "jobs2"
    names = sorted(p.name for p in one.iterdir())
    assert names == sorted(p.name for p in two.iterdir())
    assert {f"{scenario}.{kind}" for scenario in SHORT_ALL for kind in ("csv", "txt", "png", "json")} <= set(names)
    for name in names:
        if name.endswith(".json"):
            assert _record(one / name) == _record(two / name), name
        elif not name.endswith(".svg"):      # SVG element ids are random in every run
            assert (one / name).read_bytes() == (two / name).read_bytes(), name


def test_report_runs_the_missing_scenarios_in_its_jobs(tmp_path, monkeypatch):
    """``obsfmu report --jobs N`` hands the scenarios without results to the runner of ``obsfmu all --jobs N``."""
    calls = []
    monkeypatch.setattr(commands, "run_and_report", lambda out, build_dir, names, jobs=1: calls.append((names, jobs)) or 0)
    assert cli.main(["report", "--out", str(tmp_path / "r"), "--build-dir", str(tmp_path / "b"), "--jobs", "2"]) == 0
    assert calls == [(list(SCENARIOS), 2)]


def test_a_failing_scenario_is_named_and_the_others_still_finish(build_dir, tmp_path, capsys):
    """``N[1] = 0`` makes the ship observer refuse its parameters; discrete-gpebo still writes its files."""
    settings = {"ship": {"stop_time": 0.05, "overrides": [("observer", "N[1]", 0.0)]},
                "discrete-gpebo": {"stop_time": 10.0}}
    assert _run_all_short(tmp_path / "out", build_dir, 2, settings) == 2
    err = capsys.readouterr().err
    assert "obsfmu: error: ship: observer: " in err and "N: not Hurwitz" in err and "Traceback" not in err
    assert (tmp_path / "out" / "discrete-gpebo.json").exists() and not (tmp_path / "out" / "ship.json").exists()


_INTERRUPTIBLE = """
import sys
from pathlib import Path

from obsfmu.fmus.cli.commands import run_into
from obsfmu.fmus.cli.stopping import StopRequest

if __name__ == "__main__":   # the workers are spawned: they import this file as a module
    settings = {"ship": {"stop_time": 1e5, "step": 1e-3}, "uio-ftdrem": {"stop_time": 1e5}}   # run until stopped
    with StopRequest() as stop:
        sys.exit(run_into(Path(sys.argv[1]), Path(sys.argv[2]), list(settings), stop, 2, settings))
"""


def test_ctrl_c_stops_every_worker_after_its_step_without_a_traceback(build_dir, tmp_path):
    """SIGINT to the whole process group (a terminal's Ctrl-C) while two workers run: exit 130, each
    scenario interrupted with its rows kept in NAME.partial.csv, no traceback from any process."""
    import subprocess
    import sys
    import time

    ensure_fmus(get("ship"), build_dir), ensure_fmus(get("uio-ftdrem"), build_dir)
    script, out = tmp_path / "interruptible.py", tmp_path / "out"
    script.write_text(_INTERRUPTIBLE)
    out.mkdir()
    process = subprocess.Popen([sys.executable, str(script), str(out), str(build_dir)], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.monotonic() + 120
    while not all(list(out.glob(f".{name}.csv.*")) for name in ("ship", "uio-ftdrem")):   # both runs stepping
        assert process.poll() is None and time.monotonic() < deadline, process.communicate()
        time.sleep(0.1)
    os.killpg(process.pid, signal.SIGINT)
    stdout, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, stderr
    assert "Traceback" not in stderr + stdout and "KeyboardInterrupt" not in stderr
    for name in ("ship", "uio-ftdrem"):
        assert f"{name}: interrupted at t = " in stdout
        assert (out / f"{name}.partial.csv").exists() and not (out / f"{name}.csv").exists()
    assert stdout.index("ship: interrupted") < stdout.index("uio-ftdrem: interrupted")


def test_a_step_far_beyond_the_default_warns_with_the_expected_growth(ship_build, capsys):
    """``--step 0.3`` on ship (default 2e-5 s) ran to an error of 1.75e4 without a word: now one line says
    how far the step is from the default and how the coupling error grows; a step near it says nothing."""
    assert cli.main(["run", "ship", "--build-dir", ship_build, "--step", "0.3", "--stop-time", "0.6"]) == 0
    warnings = [line for line in capsys.readouterr().err.splitlines() if "warning: --step" in line]
    assert warnings == ["obsfmu: warning: --step 0.3 s is 1.5e+04 times ship's default 2e-05 s: with linear "
                        "coupling the coupling error grows like h^2, to about 2.2e+08 times the error at the "
                        "default (README: Choosing the communication step)"]
    assert cli.main(["run", "ship", "--build-dir", ship_build, "--step", "1e-4", "--stop-time", "0.01",
                     "--coupling", "hold"]) == 0
    assert "warning: --step" not in capsys.readouterr().err


def test_fmus_are_built_in_the_checkout_or_the_cache_never_in_the_working_directory(tmp_path, monkeypatch):
    """Issue 38: `obsfmu run` started elsewhere wrote ./build there.  The default build folder is the checkout's
    build/ (a source tree: pyproject.toml beside fmus/) or, for an installed obsfmu, $OBSFMU_CACHE/build."""
    from obsfmu.fmus.caches import default_build_dir
    from obsfmu.fmus.cli.args import DEFAULT_BUILD

    root = Path(__file__).resolve().parents[3]
    assert DEFAULT_BUILD == default_build_dir() == root / "build"
    installed = tmp_path / "site-packages" / "obsfmu"
    (installed / "fmus").mkdir(parents=True)
    monkeypatch.setenv("OBSFMU_CACHE", str(tmp_path / "cache"))
    assert default_build_dir(installed) == tmp_path / "cache" / "build"
    monkeypatch.delenv("OBSFMU_CACHE")
    assert default_build_dir(installed) == Path.home() / ".cache" / "obsfmu" / "build"


def test_the_progress_bar_shows_in_a_pseudo_terminal_of_any_size(build_dir):
    """Issue 38: no bar was seen in a pseudo-terminal: one that reports 0 x 0 (script, pty.fork, CI runners)
    made tqdm draw nothing.  A run of a few seconds in such a terminal shows the bar (model time and percent).  The
    bar waits 1 s before it draws: the run is on the Python path (with its compiled kernels ltv-ls takes 0.1 s)."""
    import pty
    import select

    pid, fd = pty.fork()
    if pid == 0:                                    # the child: obsfmu run in the pseudo-terminal
        os.execve(sys.executable, [sys.executable, "-m", "obsfmu", "run", "ltv-ls", "--stop-time", "3",
                                   "--build-dir", str(build_dir)], {**os.environ, "OBSFMU_KERNELS": "python"})
    out = b""
    while select.select([fd], [], [], 300)[0]:
        try:
            data = os.read(fd, 65536)
        except OSError:                             # the child ended: the pseudo-terminal is closed
            break
        if not data:
            break
        out += data
    _, status = os.waitpid(pid, 0)
    text = out.decode(errors="replace")
    assert os.waitstatus_to_exitcode(status) == 0, text
    assert "%|" in text and "t = 3/3 s" in text and "steps" in text, text[-2000:]
