"""``obsfmu sweep``: the campaign's command line (:data:`SUBCOMMAND`, listed by :mod:`fmus.cli.main`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..cli.subcommand import Subcommand

__all__ = ["configure", "cmd_sweep", "SUBCOMMAND"]

EXAMPLES = """examples:
  obsfmu sweep ltv-ls-bounded --vary 'plant.k[1]=uniform(-4,-2)' --vary 'plant.x0[1]=normal(2,0.5)' \\
               --samples 32 --seed 1 --stop-time 30 --workers 2 --out results/ltv
  obsfmu sweep uio-ftdrem --vary plant.omega=0.5:2:4 --vary 'plant.noise_std=[0, 1e-3, 1e-2]'
  obsfmu sweep --config study.toml --scheduler tcp://SCHEDULER_HOST:8786

SPEC: a grid LO:HI:COUNT, a list [a, b, c] or a,b,c, or uniform(lo, hi), normal(mean, std),
loguniform(lo, hi) (random specs need --samples; every grid point gets the same draws).
Rerunning the same command computes only the samples missing from --out.  See docs/campaigns.md."""


def configure(sweep: argparse.ArgumentParser) -> None:
    """The options of ``obsfmu sweep``."""
    from ..cli.args import duration, positive_int
    from ..master import COUPLINGS, ORDERS

    sweep.add_argument("scenario", nargs="?", help="scenario name (obsfmu list); optional with --config")
    sweep.add_argument("--config", metavar="FILE.toml", help="a system file (docs/your-own-system.md), or the "
                       "campaign as a TOML file (docs/campaigns.md); "
                       "options given here override it")
    sweep.add_argument("--vary", action="append", metavar="INSTANCE.VAR=SPEC",
                       help="a varied parameter, e.g. plant.k[1]=-3:3:7 or 'plant.x0[1]=uniform(-1,1)' (repeatable)")
    sweep.add_argument("--samples", type=positive_int, help="number of random draws (with random specs)")
    sweep.add_argument("--seed", type=int, help="seed of the random draws (default 0)")
    where = sweep.add_mutually_exclusive_group()
    where.add_argument("--workers", type=positive_int, help="worker processes of the local Dask cluster "
                       "(default: the machine's cores)")
    where.add_argument("--scheduler", metavar="ADDR", help="address of a running Dask scheduler, "
                       "e.g. tcp://HOST:8786 (see 'dask scheduler' / 'dask worker')")
    sweep.add_argument("--dashboard", type=_address, metavar="HOST:PORT",
                       help="serve the local cluster's Dask dashboard at HOST:PORT and print its link, e.g. "
                            "127.0.0.1:8787, or 0.0.0.0:8787 to open it to the network (anyone who reaches the "
                            "port sees the workers and the tasks).  Default: 127.0.0.1 on a free port, not "
                            "announced; the scheduler and workers listen on 127.0.0.1 only, always")
    sweep.add_argument("--out", help="campaign directory (default: results/sweep-SCENARIO)")
    sweep.add_argument("--stop-time", type=duration, help="stop time (default: the scenario's), in its unit of "
                       "time unless given: 30, 90min")
    sweep.add_argument("--step", type=duration, help="communication step (default: the scenario's), "
                       "same units")
    sweep.add_argument("--master", choices=ORDERS, help="stepping order (default: the scenario's)")
    sweep.add_argument("--tol", type=float, help="adaptive master: error per unit step (default: the scenario's, "
                       "1e-6)")
    sweep.add_argument("--coupling", choices=COUPLINGS, help="inputs inside a step (default: the scenario's)")
    sweep.add_argument("--set", action="append", metavar="INSTANCE.VAR=VALUE",
                       help="a start value fixed for every sample (repeatable)")
    sweep.add_argument("--time-limit", type=float, metavar="SECONDS",
                       help="wall time allowed per sample; a sample over it is a row with status timeout "
                            "(default 600)")
    sweep.add_argument("--time-metric", metavar="NAME[,NAME]", help="summary metric(s) whose max is the "
                       "convergence time (default: the scenario's, see docs/campaigns.md)")
    sweep.add_argument("--error-metric", metavar="NAME[,NAME]", help="summary metric(s) whose max |.| is the "
                       "final error (default: the scenario's)")
    sweep.add_argument("--retry-failed", action="store_true", help="also recompute stored samples that failed")
    sweep.add_argument("--report-only", action="store_true", help="compute nothing: table, summary and figures "
                       "from the samples stored in --out (also those computed with FMUs built before a change)")
    sweep.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                       help="progress bar on stderr (default: only on a terminal)")
    sweep.add_argument("--no-plots", action="store_true", help="do not write the figures")
    sweep.add_argument("--build-dir", help="where the FMUs are (built if missing; default build)")


def _address(text: str) -> str:
    """``HOST:PORT`` (argparse type; an empty HOST is every interface, as for Dask)."""
    host, colon, port = text.strip().rpartition(":")
    if not colon or not port.isdigit() or not 0 <= int(port) <= 65535 or any(c.isspace() for c in host):
        raise argparse.ArgumentTypeError(f"{text!r}: expected HOST:PORT, e.g. 127.0.0.1:8787")
    return f"{host}:{int(port)}"


def _pairs(items, option: str) -> dict[str, str]:
    pairs = {}
    for item in items or []:
        name, equals, value = item.partition("=")
        if not equals or not name.strip() or not value.strip():
            raise _error(f"{option} {item!r}: expected INSTANCE.VARIABLE={'SPEC' if option == '--vary' else 'VALUE'}")
        if name.strip() in pairs:
            raise _error(f"{option} {name.strip()}: given twice")
        pairs[name.strip()] = value.strip()
    return pairs


def _error(text: str):
    from .errors import CampaignError
    return CampaignError(text)


def campaign_from_args(args):
    """The :class:`~fmus.campaign.design.Campaign` described by the command line (and ``--config``)."""
    from .design import Campaign

    options = {"scenario": args.scenario, "samples": args.samples, "seed": args.seed, "master": args.master,
               "coupling": args.coupling, "tolerance": args.tol,
               "time_limit": args.time_limit, "time_metric": args.time_metric, "error_metric": args.error_metric,
               "build_dir": args.build_dir, "vary": _pairs(args.vary, "--vary"), "set": _pairs(args.set, "--set")}
    from ..system.commands import holds_components, require_rereadable
    if args.config:
        require_rereadable(args.config, "sweep")
    if args.config and holds_components(args.config):   # a system file: its scenario
        from ..system.commands import scenario_key
        options["scenario"] = scenario_key(args)
        campaign = Campaign(**{k: v for k, v in options.items() if v is not None})
    elif args.config:
        campaign = Campaign.from_toml(args.config, **options)
    elif not args.scenario:
        raise _error("sweep: give a SCENARIO (obsfmu list) or --config FILE.toml")
    else:
        campaign = Campaign(**{k: v for k, v in options.items() if v is not None})
    return _with_times(campaign, args)


def _with_times(campaign, args):
    """``--stop-time``/``--step`` in the scenario's unit of time (as for ``obsfmu run``)."""
    from .. import scenarios
    from ..cli.args import scenario_times

    if args.stop_time is not None or args.step is not None:
        times = scenario_times(args, scenarios.get(campaign.scenario))
        for key in ("stop_time", "step"):
            if times[key] is not None:
                setattr(campaign, key, times[key])
    return campaign


def cmd_sweep(args) -> int:
    from ..cli.stopping import interrupted_status
    from .runner import run_campaign
    from .table import summary_text

    campaign = campaign_from_args(args)
    plan = campaign.plan()
    out = Path(args.out or Path("results") / f"sweep-{plan.scenario.name}")
    print(f"{plan.scenario.name}: {len(plan.samples)} samples, stop time {plan.settings['stop_time']:g} "
          f"{plan.scenario.time_unit}, step {plan.settings['step']:g}, {plan.settings['order']}; "
          f"results in {out}", flush=True)
    try:
        table = run_campaign(plan, workers=args.workers, scheduler=args.scheduler, out=out, progress=args.progress,
                             retry_failed=args.retry_failed, report_only=args.report_only,
                             plots=not args.no_plots, dashboard=args.dashboard)
    except KeyboardInterrupt as exc:  # Ctrl-C, SIGTERM or SIGHUP (fmus.cli.Terminated)
        print(f"\ninterrupted: every finished sample is in {out / 'samples'}; rerun the same command to compute "
              f"the rest ({exc or 'SIGINT'})", file=sys.stderr)
        return interrupted_status(exc)
    print(summary_text(plan, table))
    written = [out / "samples", out / "samples.csv", out / "summary.txt"]
    if not args.no_plots and table.num_rows:
        written += [out / f"{name}.png" for name in ("convergence", "error_vs_inputs", "convergence_vs_inputs")]
    print("wrote " + ", ".join(str(p) for p in written) + " (figures also as .svg)" * (not args.no_plots))
    return 0


SUBCOMMAND = Subcommand(
    "sweep", "run a scenario over many parameter values on Dask (grid / Monte-Carlo study)", configure, cmd_sweep,
    epilog="Sweep or Monte-Carlo study of a scenario: one row per sample (inputs, status, convergence time, final "
           "error, the scenario's summary metrics) in OUT/samples (Parquet) and OUT/samples.csv, a summary and "
           "figures.\n\n" + EXAMPLES)
