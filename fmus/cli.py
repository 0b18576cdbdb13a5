"""Command line: ``obsfmu build | list | run | all``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from observers.checks import ParameterError

from .master import COUPLINGS, ORDERS, SimulationError

DEFAULT_BUILD = Path("build")


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


def cmd_build(args) -> int:
    from .builder import build_fmu
    from .scenarios import SCENARIOS, ensure_all

    out = Path(args.out)
    if args.config:
        from .config import design_from_config, load_config
        design = design_from_config(load_config(args.config))
        paths = [build_fmu(definition, out) for definition in design.definitions()]
    else:
        paths = list(ensure_all(SCENARIOS.values(), out, force=True).values())   # each FMU once
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


def _write_outputs(scenario, result, summary, csv: Path | None, png: Path | None, text: Path | None,
                   interval: float | None = None):
    if csv:
        (result.sampled(interval) if interval else result).to_csv(csv)
        print(f"wrote {csv}")
    if png and scenario.plot:
        scenario.plot(result, png)
        print(f"wrote {png}")
    if text and summary:
        text.write_text(str(summary) + "\n")


def cmd_run(args) -> int:
    from . import scenarios

    scenario = scenarios.get(args.scenario)
    overrides = scenarios.parse_overrides(args.set or [])
    result, summary = scenarios.run(args.scenario, args.build_dir, stop_time=args.stop_time, step=args.step,
                                    order=args.master, coupling=args.coupling, overrides=overrides,
                                    progress=sys.stderr.isatty(), tolerance=args.tol)
    print(f"{scenario.name}: {len(result.time) - 1} steps to t = {result.time[-1]:g} s")
    if summary:
        print(summary)
    _write_outputs(scenario, result, summary, args.csv and Path(args.csv), args.plot and Path(args.plot), None,
                   args.output_interval)
    return 0


def cmd_export(args) -> int:
    from . import scenarios
    from .export import export

    path = export(scenarios.get(args.scenario), args.format, args.out, args.build_dir, step=args.step,
                  stop_time=args.stop_time, overrides=scenarios.parse_overrides(args.set or []),
                  coupling=args.coupling)
    print(f"wrote {path}")
    return 0


def cmd_all(args) -> int:
    """The main job: build every FMU, validate it, run every scenario, write CSV + PNG + summary."""
    from .scenarios import SCENARIOS, run

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if cmd_build(argparse.Namespace(config=None, out=args.build_dir)):
        print("some FMUs are not valid", file=sys.stderr)
        return 1
    for name, scenario in SCENARIOS.items():
        print(f"\n== {name}: {scenario.description}")
        result, summary = run(name, args.build_dir, progress=sys.stderr.isatty())
        if summary:
            print(summary)
        _write_outputs(scenario, result, summary, out / f"{name}.csv", out / f"{name}.png", out / f"{name}.txt",
                       scenario.output_interval)
    return 0


def parser() -> argparse.ArgumentParser:
    main = argparse.ArgumentParser(prog="obsfmu", description="Adaptive observers as FMI 2.0 co-simulation FMUs")
    commands = main.add_subparsers(dest="command", required=True)

    build = commands.add_parser("build", help="build FMUs (all scenarios, or one TOML design)")
    build.add_argument("--config", help="TOML design file of your own plant (see fmus/config.py)")
    build.add_argument("--out", default=str(DEFAULT_BUILD), help="output directory (default: build)")
    build.set_defaults(func=cmd_build)

    listing = commands.add_parser("list", help="list the scenarios")
    listing.set_defaults(func=cmd_list)

    run = commands.add_parser("run", help="co-simulate a scenario")
    run.add_argument("scenario")
    run.add_argument("--stop-time", type=float, help="stop time in s (default: the scenario's)")
    run.add_argument("--step", type=float, help="communication step in s (default: the scenario's)")
    run.add_argument("--master", choices=ORDERS, help="stepping order (default: the scenario's); adaptive: "
                     "step doubling with rollback to --tol")
    run.add_argument("--tol", type=float, default=1e-6,
                     help="adaptive master: error per unit step on every output (default 1e-6)")
    run.add_argument("--coupling", choices=COUPLINGS,
                     help="inputs inside a step: linear (interpolate/extrapolate) or hold")
    run.add_argument("--set", action="append", metavar="INSTANCE.VAR=VALUE",
                     help="start value of a parameter or input, e.g. plant.x0[1]=0.1 (repeatable)")
    run.add_argument("--csv", help="write every output at every communication point")
    run.add_argument("--output-interval", type=float,
                     help="write only the rows nearest to multiples of this interval to the CSV")
    run.add_argument("--plot", help="write a PNG figure")
    run.add_argument("--build-dir", default=str(DEFAULT_BUILD), help="where the FMUs are (built if missing)")
    run.set_defaults(func=cmd_run)

    exporting = commands.add_parser("export", help="write a scenario as an SSP package or OSP system structure")
    exporting.add_argument("scenario")
    exporting.add_argument("--format", choices=("ssp", "osp"), required=True)
    exporting.add_argument("--out", required=True, help="output directory")
    exporting.add_argument("--step", type=float, help="communication step (default: the scenario's)")
    exporting.add_argument("--stop-time", type=float, help="stop time (default: the scenario's)")
    exporting.add_argument("--coupling", choices=COUPLINGS,
                           help="linear: connected inputs extrapolate inside the FMUs (default: the scenario's)")
    exporting.add_argument("--set", action="append", metavar="INSTANCE.VAR=VALUE")
    exporting.add_argument("--build-dir", default=str(DEFAULT_BUILD))
    exporting.set_defaults(func=cmd_export)

    everything = commands.add_parser("all", help="main job: build all FMUs and run every scenario")
    everything.add_argument("--out", default="results", help="directory for CSV, PNG and summaries")
    everything.add_argument("--build-dir", default=str(DEFAULT_BUILD))
    everything.set_defaults(func=cmd_all)
    return main


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        return args.func(args)
    except (ParameterError, SimulationError) as exc:
        print(f"obsfmu: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
