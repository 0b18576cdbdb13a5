"""Running one scenario from the command line: its CSV streamed, its files and record written."""

from __future__ import annotations

import sys
import time as wallclock
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ..output import StreamingRecorder, check_file
from .stopping import StopRequest

if TYPE_CHECKING:
    from ..result import Result
    from ..scenarios import Summary

__all__ = ["Outcome", "run_scenario", "run_one", "report_interrupted", "build_all", "report_built", "validate",
           "figure_paths"]

def validate(path: Path) -> list[str]:
    from ..validation import validate_fmu
    return validate_fmu(path)


def report_built(paths) -> int:
    failures = 0
    for path in paths:
        problems = validate(path)
        failures += bool(problems)
        status = "valid" if not problems else "INVALID: " + "; ".join(problems)
        print(f"{path}  ({status})")
    return failures


def build_all(build_dir: Path, fmi_version: int = 2, standalone: bool = False, platforms=None,
              force: bool = False, kernels: str = "c") -> list[Path]:
    """Every distinct FMU of the scenarios, each built once (ltv-ls and ltv-ls-bounded share theirs), with
    binaries for ``platforms`` (default: this machine's); one that is current (judged by content,
    :func:`fmus.builder.why_not_current`) is kept unless ``force``."""
    from ..scenarios import SCENARIOS, ensure_all
    return list(ensure_all(SCENARIOS.values(), build_dir, force=force, fmi_version=fmi_version,
                           standalone=standalone, platforms=platforms, kernels=kernels).values())


def figure_paths(option: str, path: str) -> list[Path]:
    from ..plotting import FORMATS, companion_paths
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


def run_scenario(name: str, build_dir: Path, stop: StopRequest, csv: Path | None, interval: float | None,
                 option: str = "--csv", **settings) -> Outcome:
    """Run ``name`` streaming to ``csv`` (named by ``option``); the CSV is complete, or partial if the run
    stopped early."""
    from .. import scenarios
    recorder = StreamingRecorder(csv, interval, option=option)
    started = wallclock.perf_counter()
    try:
        result, summary = scenarios.run(name, build_dir, recorder=recorder, should_stop=stop,
                                        progress=sys.stderr.isatty(), **settings)
    except BaseException:
        if recorder.rows and csv is not None:
            if kept := recorder.close(complete=False):   # None: the CSV's own error said where its rows are
                print(f"obsfmu: the rows computed before the error are in {kept}", file=sys.stderr)
        else:
            recorder.discard()
        raise
    written = recorder.close(complete=not result.interrupted)
    return Outcome(result, summary, written, wallclock.perf_counter() - started)


def report_interrupted(outcome: Outcome, name: str, stop: StopRequest) -> int:
    result = outcome.result
    kept = f"; the rows so far are in {outcome.csv}" if outcome.csv else " (nothing written)"
    print(f"{name}: interrupted at t = {result.time[-1]:g} {result.time_unit}{kept}")
    return stop.exit_code


def run_one(out: Path, build_dir: Path, name: str, stop: StopRequest, settings: dict | None = None) -> int:
    """Run scenario ``name`` (its defaults, or ``settings`` for :func:`fmus.scenarios.run`), write its files
    and record into ``out``, print its summary; 0, or 128 + the signal if it was interrupted."""
    from .. import report
    from ..scenarios import get
    scenario = get(name)
    print(f"\n== {scenario.name}: {scenario.description}")
    outcome = run_scenario(name, build_dir, stop, out / f"{scenario.name}.csv", scenario.output_interval, "--out",
                           **(settings or {}))
    if outcome.result.interrupted:
        return report_interrupted(outcome, name, stop)
    if outcome.summary:
        print(outcome.summary)
    report.save_run(out, scenario, outcome.result, outcome.summary, outcome.wall_time, build_dir)
    print(f"wrote {out / scenario.name}.csv, .png, .svg, .txt, .json")
    return 0
