"""Command line: ``obsfmu build | list | run | export | all | report``.

Every user mistake ends in one line ``obsfmu: error: <argument or field>: <what is wrong>`` and exit
code 2 -- bad option values are refused by the argument parser, output paths are checked before
anything is simulated, and the remaining checks raise :class:`ParameterError`,
:class:`SimulationError` or :class:`OutputError`, which :func:`main` prints.  Ctrl-C during a run
stops it after the current communication step (exit 130, the rows so far kept in a file marked
partial).

Subcommands are registered with :func:`register`; a module that adds one (e.g. ``obsfmu sweep``)
calls ``register(...)`` at import and is imported once at the end of this file.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import signal
import sys
import threading
import time as wallclock
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from observers.checks import ParameterError

from .master import COUPLINGS, ORDERS, SimulationError
from .output import OutputError, StreamingRecorder, check_directory, check_file

if TYPE_CHECKING:
    from .result import Result
    from .scenarios import Summary

__all__ = ["main", "parser", "register", "Subcommand"]

DEFAULT_BUILD = Path("build")
DEFAULT_RESULTS = Path("results")
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130  #: 128 + SIGINT, what a shell reports for a Ctrl-C


# ----------------------------------------------------------------------------- registry
@dataclass
class Subcommand:
    """``obsfmu NAME``: ``configure(parser)`` adds its arguments, ``handler(args)`` runs it (exit code)."""

    name: str
    help: str
    configure: Callable[[argparse.ArgumentParser], None]
    handler: Callable[[argparse.Namespace], int]
    epilog: str | Callable[[], str] | None = None


SUBCOMMANDS: dict[str, Subcommand] = {}


def register(name: str, help: str, configure: Callable[[argparse.ArgumentParser], None],
             handler: Callable[[argparse.Namespace], int], epilog: str | Callable[[], str] | None = None) -> None:
    """Add ``obsfmu NAME``; ``epilog`` (text after the options in ``--help``) may be a function,
    called when the parser is built."""
    if name in SUBCOMMANDS:
        raise ValueError(f"subcommand {name!r} registered twice")
    SUBCOMMANDS[name] = Subcommand(name, help, configure, handler, epilog)


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (exit 2), pointing to ``--help``."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


# ----------------------------------------------------------------------------- value types
_TIME = re.compile(r"^\s*(?P<number>\S+?)\s*(?P<unit>s|min|h|d)?\s*$")
TIME_UNITS = {"s": 1.0, "min": 60.0, "h": 3600.0, "d": 86400.0}


def _positive(text: str) -> float:
    """A finite number > 0 (argparse type)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a positive finite number, got {text}")
    return value


def _positive_int(text: str) -> int:
    """An integer >= 1 (argparse type)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


@dataclass(frozen=True)
class Duration:
    """A time given on the command line: a number in the scenario's unit, or with its own unit."""

    value: float
    unit: str | None = None

    def in_unit(self, unit: str) -> float:
        if self.unit is None or self.unit == unit:
            return self.value
        return self.value * TIME_UNITS[self.unit] / TIME_UNITS[unit]


def _duration(text: str) -> Duration:
    """``30``, ``30 h``, ``90min``, ``2e-3s`` -> :class:`Duration` (finite and > 0; argparse type)."""
    match = _TIME.match(text)
    try:
        float(match["number"] if match else text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a time: a number, optionally followed by "
                                         f"{', '.join(TIME_UNITS)}") from None
    value = _positive(match["number"])
    return Duration(value, match["unit"].lower() if match["unit"] else None)


def _scenario_list_help() -> str:
    from .scenarios import SCENARIOS
    width = max(len(name) for name in SCENARIOS)
    lines = "\n".join(f"  {name:<{width}}  [{scenario.time_unit}]  {scenario.description}"
                      for name, scenario in SCENARIOS.items())
    return ("scenarios [unit of time] (defaults: 'obsfmu list'):\n" + lines
            + "\n\ntimes (--stop-time, --step, --output-interval) are in the scenario's unit of time unless "
              "one is given: 90min, 2h, 7.2s")


# ----------------------------------------------------------------------------- Ctrl-C
class StopRequest:
    """While active, SIGINT only sets a flag (the master asks it after every communication point).

    The FMUs run Python code in this interpreter, so no exception may be raised inside them.  A
    second Ctrl-C kills the process at once (it leaves only hidden temporary files behind).
    """

    def __init__(self, quiet: bool = False, shared=None):
        self.requested = False
        self.quiet = quiet      # no message (a worker process of 'obsfmu all --jobs N')
        self.shared = shared    # a shared byte (multiprocessing RawValue) another process may set
        self._previous = None

    def __call__(self) -> bool:
        return self.requested or bool(self.shared is not None and self.shared.value)

    def _handle(self, signum, frame) -> None:
        if self.requested:
            signal.signal(signal.SIGINT, signal.SIG_DFL)
            os.kill(os.getpid(), signal.SIGINT)
            return
        self.requested = True
        if not self.quiet:
            print("\nobsfmu: stopping after the current step (Ctrl-C again to kill at once)", file=sys.stderr,
                  flush=True)

    def __enter__(self) -> "StopRequest":
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)


# ----------------------------------------------------------------------------- shared steps
def _validate(path: Path) -> list[str]:
    from .validation import validate_fmu
    return validate_fmu(path)


def _report_built(paths) -> int:
    failures = 0
    for path in paths:
        problems = _validate(path)
        failures += bool(problems)
        status = "valid" if not problems else "INVALID: " + "; ".join(problems)
        print(f"{path}  ({status})")
    return failures


def _build_all(build_dir: Path, fmi_version: int = 2, standalone: bool = False) -> list[Path]:
    """Every distinct FMU of the scenarios, each built once (ltv-ls and ltv-ls-bounded share theirs)."""
    from .scenarios import SCENARIOS, ensure_all
    return list(ensure_all(SCENARIOS.values(), build_dir, force=True, fmi_version=fmi_version,
                           standalone=standalone).values())


def _figure_paths(option: str, path: str) -> list[Path]:
    from .plotting import FORMATS, companion_paths
    figures = companion_paths(check_file(option, path, FORMATS))
    for companion in figures[1:]:
        check_file(f"{option} (vector companion)", companion)
    return figures


@dataclass
class Outcome:
    """One scenario run written to disk."""

    result: Result
    summary: Summary | None
    csv: Path | None
    wall_time: float


def _run_scenario(name: str, build_dir: Path, stop: StopRequest, csv: Path | None, interval: float | None,
                  **settings) -> Outcome:
    """Run ``name`` streaming to ``csv``; the CSV is complete, or partial if the run stopped early."""
    from . import scenarios
    recorder = StreamingRecorder(csv, interval)
    started = wallclock.perf_counter()
    try:
        result, summary = scenarios.run(name, build_dir, recorder=recorder, should_stop=stop,
                                        progress=sys.stderr.isatty(), **settings)
    except BaseException:
        if recorder.rows and csv is not None:
            kept = recorder.close(complete=False)
            print(f"obsfmu: the rows computed before the error are in {kept}", file=sys.stderr)
        else:
            recorder.discard()
        raise
    written = recorder.close(complete=not result.interrupted)
    return Outcome(result, summary, written, wallclock.perf_counter() - started)


def _interrupted(outcome: Outcome, name: str) -> int:
    result = outcome.result
    kept = f"; the rows so far are in {outcome.csv}" if outcome.csv else " (nothing written)"
    print(f"{name}: interrupted at t = {result.time[-1]:g} {result.time_unit}{kept}")
    return EXIT_INTERRUPTED


# ----------------------------------------------------------------------------- subcommands
def cmd_build(args) -> int:
    from .builder import build_fmu

    from .fmi3 import build_folder

    out = check_directory("--out", args.out)
    if args.config:
        from .config import design_from_config, load_config
        design = design_from_config(load_config(args.config))
        paths = [build_fmu(definition, build_folder(out, args.fmi_version), fmi_version=args.fmi_version,
                           standalone=args.standalone) for definition in design.definitions()]
    else:
        paths = _build_all(out, args.fmi_version, args.standalone)
    return 1 if _report_built(paths) else 0


def cmd_list(args) -> int:
    from .scenarios import SCENARIOS
    width = max(len(name) for name in SCENARIOS)
    for name, scenario in SCENARIOS.items():
        print(f"{name:<{width}}  {scenario.description}")
        unit = scenario.time_unit
        print(f"{'':<{width}}  defaults: stop {scenario.stop_time:g} {unit}, step {scenario.step:g} {unit}, "
              f"{scenario.order}, {scenario.coupling} coupling")
    return 0


def _times(args, scenario) -> dict[str, float | None]:
    unit = scenario.time_unit
    return {key: None if getattr(args, key, None) is None else getattr(args, key).in_unit(unit)
            for key in ("stop_time", "step", "output_interval")}


def cmd_run(args) -> int:
    from . import scenarios

    scenario = scenarios.get(args.scenario)
    times = _times(args, scenario)
    overrides = scenarios.parse_overrides(args.set or [])
    csv = check_file("--csv", args.csv) if args.csv else None
    figures = _figure_paths("--plot", args.plot) if args.plot else []
    build_dir = check_directory("--build-dir", args.build_dir, writable=False)
    with StopRequest() as stop:
        outcome = _run_scenario(scenario.name, build_dir, stop, csv, times["output_interval"],
                                stop_time=times["stop_time"], step=times["step"], order=args.master,
                                coupling=args.coupling, overrides=overrides, tolerance=args.tol,
                                fmi_version=args.fmi_version)
        result, summary = outcome.result, outcome.summary
        if result.interrupted:
            return _interrupted(outcome, scenario.name)
        print(f"{scenario.name}: {len(result.time) - 1} steps to t = {result.time[-1]:g} {result.time_unit}")
        if summary:
            print(summary)
        if csv:
            print(f"wrote {outcome.csv}")
        if figures and scenario.plot:
            print("wrote " + ", ".join(str(p) for p in scenario.plot(result, figures[0])))
    return 0


def cmd_export(args) -> int:
    from . import scenarios
    from .export import export

    scenario = scenarios.get(args.scenario)
    times = _times(args, scenario)
    out = check_directory("--out", args.out)
    build_dir = check_directory("--build-dir", args.build_dir, writable=False)
    path = export(scenario, args.format, out, build_dir, step=times["step"], stop_time=times["stop_time"],
                  overrides=scenarios.parse_overrides(args.set or []), coupling=args.coupling,
                  fmi_version=args.fmi_version, system_outputs=args.system_outputs, standalone=args.standalone)
    print(f"wrote {path}")
    return 0


def _run_one(out: Path, build_dir: Path, name: str, stop: StopRequest, settings: dict | None = None) -> int:
    """Run scenario ``name`` (its defaults, or ``settings`` for :func:`fmus.scenarios.run`), write its files
    and record into ``out``, print its summary; 0, or 130 if it was interrupted."""
    from . import report
    from .scenarios import get
    scenario = get(name)
    print(f"\n== {name}: {scenario.description}")
    outcome = _run_scenario(name, build_dir, stop, out / f"{name}.csv", scenario.output_interval, **(settings or {}))
    if outcome.result.interrupted:
        return _interrupted(outcome, name)
    if outcome.summary:
        print(outcome.summary)
    report.save_run(out, scenario, outcome.result, outcome.summary, outcome.wall_time, build_dir)
    print(f"wrote {out / name}.csv, .png, .svg, .txt, .json")
    return 0


def _run_into(out: Path, build_dir: Path, names, stop: StopRequest, jobs: int = 1,
              settings: dict[str, dict] | None = None) -> int:
    """Run every scenario in ``names`` into ``out``: one after the other, or in ``jobs`` worker processes
    (:mod:`fmus.parallel`; same files, summaries printed in the order of ``names``)."""
    if jobs > 1 and len(names) > 1:
        from .parallel import run_in_workers
        return run_in_workers(out, build_dir, list(names), stop, jobs, settings or {})
    for name in names:
        status = _run_one(out, build_dir, name, stop, (settings or {}).get(name))
        if status:
            return status
    return 0


def _run_and_report(out: Path, build_dir: Path, names: list[str], jobs: int = 1) -> int:
    """Run ``names`` into ``out`` (Ctrl-C stops them), then write the report of every scenario there."""
    from . import report
    with StopRequest() as stop:
        status = _run_into(out, build_dir, names, stop, jobs)
        if status:
            return status
        print(f"\nwrote {report.write_report(out, build_dir)}")
    return 0


def cmd_all(args) -> int:
    """The main job: build every FMU, validate it, run every scenario, write the files and the report."""
    from .scenarios import SCENARIOS

    out = check_directory("--out", args.out)
    build_dir = check_directory("--build-dir", args.build_dir)
    if _report_built(_build_all(build_dir)):
        print("obsfmu: error: some FMUs are not valid", file=sys.stderr)
        return 1
    return _run_and_report(out, build_dir, list(SCENARIOS), args.jobs)


def cmd_report(args) -> int:
    from . import report
    from .scenarios import SCENARIOS

    out = check_directory("--out", args.out)
    build_dir = check_directory("--build-dir", args.build_dir, writable=False)
    missing = [name for name in SCENARIOS if not report.has_run(out, name)]
    return _run_and_report(out, build_dir, missing, args.jobs)


# ----------------------------------------------------------------------------- arguments
def _add_scenario_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", metavar="SCENARIO", help="one of the scenarios listed below")
    parser.add_argument("--stop-time", type=_duration, metavar="T",
                        help="stop time (default: the scenario's), in its unit of time unless given: 20, 90min")
    parser.add_argument("--step", type=_duration, metavar="H",
                        help="communication step (default: the scenario's), in its unit of time unless given")
    parser.add_argument("--coupling", choices=COUPLINGS,
                        help="inputs inside a step: linear (interpolate/extrapolate through input derivatives) "
                             "or hold (default: the scenario's)")
    parser.add_argument("--set", action="append", metavar="INSTANCE.VAR=VALUE",
                        help="start value of a parameter or an unconnected input, e.g. plant.x0[1]=0.1 "
                             "(repeatable; checked against the FMU's declared type and range)")
    parser.add_argument("--build-dir", default=str(DEFAULT_BUILD), metavar="DIR",
                        help="where the FMUs are; missing, outdated or damaged ones are (re)built (default: build)")
    _add_fmi_version(parser)


def _add_fmi_version(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--fmi-version", type=int, choices=(2, 3), default=2,
                        help="FMI version of the FMUs: 2 (default) or 3 (array variables; FMI 3.0 FMUs are built "
                             "into <build dir>/fmi3; see docs/fmi3.md)")


def _configure_build(parser) -> None:
    parser.add_argument("--config", metavar="FILE.toml",
                        help="TOML design of your own LTI plant, observer and controller (see fmus/config.py, "
                             "examples/nomoto3.toml); without it: every scenario's FMUs")
    parser.add_argument("--out", default=str(DEFAULT_BUILD), metavar="DIR",
                        help="directory for the FMUs (created if missing; default: build)")
    _add_fmi_version(parser)
    _add_standalone(parser)


def _add_standalone(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--standalone", action="store_true",
                        help="FMUs that carry their own Python runtime (libpython, the standard library and numpy "
                             "modules their code imports, the libraries those load: ~27 MB each): they run on a "
                             "Linux x86-64 machine with nothing installed; see docs/portability.md")


def _configure_run(parser) -> None:
    _add_scenario_arguments(parser)
    parser.add_argument("--master", choices=ORDERS,
                        help="stepping order (default: the scenario's); adaptive: Gauss-Seidel steps with step "
                             "doubling and rollback to --tol")
    parser.add_argument("--tol", type=_positive, default=1e-6,
                        help="adaptive master: error per unit step on every output (default 1e-6)")
    parser.add_argument("--csv", metavar="FILE.csv",
                        help="write every output at every communication point, streamed as the run goes "
                             "(an interrupted run leaves FILE.partial.csv)")
    parser.add_argument("--output-interval", type=_duration, metavar="DT",
                        help="write only the rows nearest to multiples of DT to the CSV")
    parser.add_argument("--plot", metavar="FILE.png",
                        help="write the scenario's figure as FILE.png and FILE.svg (or FILE.svg/.pdf and FILE.png)")


def _configure_export(parser) -> None:
    _add_scenario_arguments(parser)
    from .export import FORMATS
    parser.add_argument("--format", choices=FORMATS, required=True,
                        help="ssp: an SSP 1.0 package SCENARIO.ssp (FMUs inside, start values as parameter "
                             "bindings, the system's outputs declared); osp: an Open Simulation Platform "
                             "OspSystemStructure.xml beside copies of the FMUs.  The FMU copies carry the start "
                             "values themselves (for importers that ignore the bindings)")
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory (created if missing)")
    parser.add_argument("--no-system-outputs", dest="system_outputs", action="store_false",
                        help="ssp: no connections to the system's output connectors (libcosim and ECOS reject "
                             "them; FMU Manipulation Toolbox needs them to expose the outputs)")
    _add_standalone(parser)


def _cpus() -> int:
    """The CPUs this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def _configure_all(parser) -> None:
    parser.add_argument("--out", default=str(DEFAULT_RESULTS), metavar="DIR",
                        help="directory for every scenario's CSV, PNG, SVG, summary and the report "
                             "(default: results)")
    parser.add_argument("--build-dir", default=str(DEFAULT_BUILD), metavar="DIR",
                        help="directory for the FMUs (default: build)")
    _add_jobs_argument(parser, "the scenarios")


def _add_jobs_argument(parser, what: str) -> None:
    parser.add_argument("--jobs", type=_positive_int, default=_cpus(), metavar="N",
                        help=f"run {what} in N worker processes, the longest first (default: the number "
                             "of CPUs, here %(default)s; 1: one after the other in this process); same files, "
                             "summaries in the same order")


def _configure_report(parser) -> None:
    parser.add_argument("--out", default=str(DEFAULT_RESULTS), metavar="DIR",
                        help="directory of the results (those of 'obsfmu all'; scenarios without results "
                             "there are run first) and of report.html (default: results)")
    parser.add_argument("--build-dir", default=str(DEFAULT_BUILD), metavar="DIR",
                        help="directory of the FMUs (default: build)")
    _add_jobs_argument(parser, "the scenarios without results")


register("build", "build FMUs (every scenario's, or those of one TOML design) and validate them",
         _configure_build, cmd_build)
register("list", "list the scenarios with their defaults", lambda parser: None, cmd_list)
register("run", "co-simulate one scenario, print its summary", _configure_run, cmd_run,
         epilog=_scenario_list_help)
register("export", "write a scenario for another tool: SSP package or OSP system structure",
         _configure_export, cmd_export, epilog=_scenario_list_help)
register("all", "main job: build and validate every FMU, run every scenario, write results and report.html",
         _configure_all, cmd_all)
register("report", "write report.html: every scenario, its paper, its checks and FMI facts on one page",
         _configure_report, cmd_report)


def parser() -> argparse.ArgumentParser:
    main_parser = _Parser(prog="obsfmu", description="Adaptive state observers as FMI 2.0 co-simulation FMUs")
    commands = main_parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in SUBCOMMANDS.values():
        epilog = command.epilog() if callable(command.epilog) else command.epilog
        sub = commands.add_parser(command.name, help=command.help, description=command.help, epilog=epilog,
                                  formatter_class=argparse.RawDescriptionHelpFormatter)
        command.configure(sub)
        sub.set_defaults(func=command.handler)
    return main_parser


def main(argv: list[str] | None = None) -> int:
    """``obsfmu ...``; returns the exit code (2: a user mistake, 130: interrupted)."""
    try:
        args = parser().parse_args(argv)
        return args.func(args)
    except SystemExit as exc:  # argparse: --help (0) or a bad argument (2, message already printed)
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    except (ParameterError, SimulationError, OutputError) as exc:
        print(f"obsfmu: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("\nobsfmu: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except OSError as exc:  # a refusal of the file system not checked beforehand: still one line
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"obsfmu: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_USAGE


from .campaign import cli as _campaign_cli  # noqa: E402,F401  registers obsfmu sweep

if __name__ == "__main__":  # python -m fmus.cli: run the imported module, where subcommands registered
    from fmus.cli import main as _main
    sys.exit(_main())
