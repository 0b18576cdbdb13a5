"""``obsfmu build | list | run | export | all | report``: each a handler and its arguments."""

from __future__ import annotations

import sys
from pathlib import Path

from .args import (DEFAULT_BUILD, DEFAULT_RESULTS, add_fmi_version, add_jobs_argument, add_platform,
                   add_scenario_arguments, add_standalone, add_system_file, duration, positive, scenario_times)
from .stopping import StopRequest
from .subcommand import Subcommand

__all__ = ["SUBCOMMANDS", "run_into", "run_and_report"]

# the master, the output files and the runs (numpy, fmpy) are imported by the handlers that use them:
# `obsfmu list` and `obsfmu --help` import neither (tests/fmus/cli/test_startup.py)


def scenario_list_help() -> str:
    from ..catalogue import entries
    SCENARIOS = entries()
    width = max(len(name) for name in SCENARIOS)
    lines = "\n".join(f"  {name:<{width}}  [{scenario.time_unit}]  {scenario.description}"
                      for name, scenario in SCENARIOS.items())
    return ("scenarios [unit of time] (defaults: 'obsfmu list'):\n" + lines
            + "\n\ntimes (--stop-time, --step, --output-interval) are in the scenario's unit of time unless "
              "one is given: 90min, 2h, 7.2s")


def cmd_build(args) -> int:
    from ..output import check_directory
    from .runs import build_all, report_built
    if args.config:  # checked whole before anything is written
        from ..system.commands import build_definitions, definitions_of
        definitions = definitions_of(args.config)
        for definition in definitions:
            definition.kernels = args.kernels
    out = check_directory("--out", args.out)
    if args.config:
        paths = build_definitions(definitions, out, args.fmi_version, args.standalone, args.platform)
    else:
        paths = build_all(out, args.fmi_version, args.standalone, args.platform, force=args.rebuild,
                          kernels=args.kernels)
    return 1 if report_built(paths) else 0


def cmd_list(args) -> int:
    from ..catalogue import entries
    SCENARIOS = entries()
    width = max(len(name) for name in SCENARIOS)
    for name, scenario in SCENARIOS.items():
        print(f"{name:<{width}}  {scenario.description}")
        unit = scenario.time_unit
        print(f"{'':<{width}}  defaults: stop {scenario.stop_time:g} {unit}, step {scenario.step:g} {unit}, "
              f"{scenario.order}, {scenario.coupling} coupling")
    return 0


def cmd_run(args) -> int:
    from .. import scenarios
    from ..output import check_directory, check_file
    from ..system.commands import scenario_key
    from .runs import figure_paths, report_interrupted, run_scenario

    key = scenario_key(args)
    scenario = scenarios.get(key)
    times = scenario_times(args, scenario)
    overrides = scenarios.parse_overrides(args.set or [])
    csv = check_file("--csv", args.csv) if args.csv else None
    figures = figure_paths("--plot", args.plot) if args.plot else []
    build_dir = check_directory("--build-dir", args.build_dir, writable=False)
    with StopRequest() as stop:
        interval = times["output_interval"] or scenario.output_interval       # the scenario's (the file's) own
        outcome = run_scenario(key, build_dir, stop, csv, interval,
                               stop_time=times["stop_time"], step=times["step"], order=args.master,
                               coupling=args.coupling, overrides=overrides, tolerance=args.tol,
                               fmi_version=args.fmi_version)
        result, summary = outcome.result, outcome.summary
        if result.interrupted:
            return report_interrupted(outcome, scenario.name, stop)
        print(f"{scenario.name}: {len(result.time) - 1} steps to t = {result.time[-1]:g} {result.time_unit}")
        if summary:
            print(summary)
        if csv:
            print(f"wrote {outcome.csv}")
        if figures and scenario.plot:
            print("wrote " + ", ".join(str(p) for p in scenario.plot(result, figures[0])))
    return stop.status      # a stop asked while the files were finished: they are complete, the exit code says it


def cmd_export(args) -> int:
    from .. import scenarios
    from ..export import export
    from ..output import check_directory
    from ..system.commands import scenario_key

    scenario = scenarios.get(scenario_key(args))
    times = scenario_times(args, scenario)
    out = check_directory("--out", args.out)
    build_dir = check_directory("--build-dir", args.build_dir, writable=False)
    path = export(scenario, args.format, out, build_dir, step=times["step"], stop_time=times["stop_time"],
                  overrides=scenarios.parse_overrides(args.set or []), coupling=args.coupling,
                  fmi_version=args.fmi_version, system_outputs=args.system_outputs, standalone=args.standalone,
                  platforms=args.platform)
    print(f"wrote {path}")
    return 0


def run_into(out: Path, build_dir: Path, names, stop: StopRequest, jobs: int = 1,
             settings: dict[str, dict] | None = None) -> int:
    """Run every scenario in ``names`` into ``out``: one after the other, or in ``jobs`` worker processes
    (:mod:`fmus.parallel`; same files, summaries printed in the order of ``names``)."""
    if jobs > 1 and len(names) > 1:
        from ..parallel import run_in_workers
        return run_in_workers(out, build_dir, list(names), stop, jobs, settings or {})
    from .runs import run_one
    for name in names:
        status = run_one(out, build_dir, name, stop, (settings or {}).get(name))
        if status:
            return status
    return 0


def run_and_report(out: Path, build_dir: Path, names: list[str], jobs: int = 1, shown=None) -> int:
    """Run ``names`` into ``out`` (Ctrl-C stops them), then write the report of every scenario there
    (or of the scenarios ``shown()`` names)."""
    from .. import report
    with StopRequest() as stop:
        status = run_into(out, build_dir, names, stop, jobs) or stop.status   # no report once a stop was asked
        if status:
            return status
        print(f"\nwrote {report.write_report(out, build_dir, shown() if shown else None)}")
    return 0


def cmd_all(args) -> int:
    """The main job: build every FMU, validate it, run every scenario, write the files and the report."""
    from ..output import check_directory
    from ..scenarios import SCENARIOS
    from .runs import build_all, report_built

    out = check_directory("--out", args.out)
    build_dir = check_directory("--build-dir", args.build_dir)
    if report_built(build_all(build_dir)):
        print("obsfmu: error: some FMUs are not valid", file=sys.stderr)
        return 1
    return run_and_report(out, build_dir, list(SCENARIOS), args.jobs)


def cmd_report(args) -> int:
    from .. import report
    from ..output import check_directory
    from ..scenarios import SCENARIOS

    out = check_directory("--out", args.out)
    build_dir = check_directory("--build-dir", args.build_dir, writable=False)
    if args.config:     # the system file's run, then the report of it and of every run there before
        from ..scenarios import get
        from ..system.commands import scenario_key
        key = scenario_key(args)
        name = get(key).name
        return run_and_report(out, build_dir, [key], 1, lambda: [
            n for n in [*SCENARIOS, *report.other_runs(out)] if n != name and report.has_run(out, n)] + [name])
    missing = [name for name in SCENARIOS if not report.has_run(out, name)]
    return run_and_report(out, build_dir, missing, args.jobs)


def configure_build(parser) -> None:
    add_system_file(parser, "its FMUs; or an older single-plant design, fmus/config.py; without it: every "
                    "scenario's FMUs")
    parser.add_argument("--out", default=str(DEFAULT_BUILD), metavar="DIR",
                        help="directory for the FMUs (created if missing; default: build)")
    add_fmi_version(parser)
    add_standalone(parser)
    add_platform(parser)
    parser.add_argument("--kernels", choices=("c", "python"), default="c",
                        help="c (default): linear blocks (LTI plant, Luenberger observer, state feedback) step in "
                             "compiled C inside the FMU, the rest in Python; python: every step in Python (the "
                             "reference path; docs/performance.md)")
    parser.add_argument("--rebuild", action="store_true",
                        help="build every scenario FMU again even if the one in --out is current (by default an "
                             "FMU is reused when its build record beside it says it is the file built from "
                             "today's sources; an FMU edited since is rebuilt)")


def configure_run(parser) -> None:
    from ..master import ORDERS
    add_scenario_arguments(parser)
    parser.add_argument("--master", choices=ORDERS,
                        help="stepping order (default: the scenario's); adaptive: Gauss-Seidel steps with step "
                             "doubling and rollback to --tol")
    parser.add_argument("--tol", type=positive,
                        help="adaptive master: error per unit step on every output (default: the scenario's, 1e-6)")
    parser.add_argument("--csv", metavar="FILE.csv",
                        help="write every output at every communication point, streamed as the run goes "
                             "(an interrupted run leaves FILE.partial.csv)")
    parser.add_argument("--output-interval", type=duration, metavar="DT",
                        help="write only the rows nearest to multiples of DT to the CSV (default: the "
                        "scenario's own, its system file's [experiment] output_interval)")
    parser.add_argument("--plot", metavar="FILE.png",
                        help="write the scenario's figure as FILE.png and FILE.svg (or FILE.svg/.pdf and FILE.png)")


def configure_export(parser) -> None:
    add_scenario_arguments(parser)
    from ..export import FORMATS
    parser.add_argument("--format", choices=FORMATS, required=True,
                        help="ssp: an SSP 1.0 package SCENARIO.ssp (FMUs inside, start values as parameter "
                             "bindings, the system's outputs declared); osp: an Open Simulation Platform "
                             "OspSystemStructure.xml beside copies of the FMUs.  The FMU copies carry the start "
                             "values themselves (for importers that ignore the bindings)")
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory (created if missing)")
    parser.add_argument("--no-system-outputs", dest="system_outputs", action="store_false",
                        help="ssp: no connections to the system's output connectors (libcosim and ECOS reject "
                             "them; FMU Manipulation Toolbox needs them to expose the outputs)")
    add_standalone(parser)
    add_platform(parser)


def configure_all(parser) -> None:
    parser.add_argument("--out", default=str(DEFAULT_RESULTS), metavar="DIR",
                        help="directory for every scenario's CSV, PNG, SVG, summary and the report "
                             "(default: results)")
    parser.add_argument("--build-dir", default=str(DEFAULT_BUILD), metavar="DIR",
                        help="directory for the FMUs (default: build)")
    add_jobs_argument(parser, "the scenarios")


def configure_report(parser) -> None:
    parser.add_argument("--out", default=str(DEFAULT_RESULTS), metavar="DIR",
                        help="directory of the results (those of 'obsfmu all'; scenarios without results "
                             "there are run first) and of report.html (default: results)")
    parser.add_argument("--build-dir", default=str(DEFAULT_BUILD), metavar="DIR",
                        help="directory of the FMUs (default: build)")
    add_jobs_argument(parser, "the scenarios without results")
    add_system_file(parser, "run into --out and added to the report")


def _system_commands():
    from ..system import commands
    return commands


SUBCOMMANDS = [
    Subcommand("build", "build FMUs (every scenario's, or those of one TOML design) and validate them",
               configure_build, cmd_build),
    Subcommand("list", "list the scenarios with their defaults", lambda parser: None, cmd_list),
    Subcommand("run", "co-simulate one scenario, print its summary", configure_run, cmd_run,
               epilog=scenario_list_help),
    Subcommand("export", "write a scenario for another tool: SSP package or OSP system structure",
               configure_export, cmd_export, epilog=scenario_list_help),
    Subcommand("all", "main job: build and validate every FMU, run every scenario, write results and report.html",
               configure_all, cmd_all),
    Subcommand("show", "print the system file's field reference, or check a system file and print what it holds",
               lambda parser: _system_commands().configure_show(parser), lambda args: _system_commands().show(args)),
    Subcommand("report", "write report.html: every scenario, its paper, its checks and FMI facts on one page",
               configure_report, cmd_report),
]
