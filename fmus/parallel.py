"""``obsfmu all --jobs N``: the scenarios in N worker processes, the longest first.

Each worker runs one scenario at a time exactly as the sequential loop does
(:func:`fmus.cli.runs.run_one`: the same CSV, figures, summary and record), with what it prints captured;
the parent prints each scenario's output in the order of ``names`` as soon as it and every scenario
before it are done, and writes the report when all are.  The longest scenario (most communication
steps) starts first, so it does not end up alone at the end.

* **Processes.** The FMUs run Python code in the process that loads them, so workers are started
  with ``spawn`` (a fresh interpreter: nothing of the parent, no loaded FMU, is inherited).  The FMUs
  are built before the pool starts (``obsfmu all``); a worker only loads them.
* **Ctrl-C** goes to the whole foreground process group.  Workers start with SIGINT ignored (no
  traceback while they boot), then take it like the parent, silently: the first stops the run after
  the current communication step (the rows so far kept in ``NAME.partial.csv``), a second kills the
  worker.  The parent's first Ctrl-C (:class:`fmus.cli.stopping.StopRequest`) also sets a shared flag every
  worker asks after each communication point (for a SIGINT sent to the parent alone) and cancels the
  scenarios not started yet; the exit code is 130.  SIGTERM and SIGHUP are taken the same way (exit
  128 + the signal: 143, 129).
* **Orphans.** Workers die with the parent, also when it is killed with SIGKILL (:mod:`fmus.orphans`).
* **Failures.** A scenario that fails does not stop the others: they finish and write their files,
  then the failure is reported as ``obsfmu: error: NAME: why`` (exit 2, no report, as the sequential
  run); an unexpected exception is re-raised in the parent with the worker's traceback.
"""

from __future__ import annotations

import concurrent.futures as futures
import contextlib
import io
import multiprocessing
import os
import signal
import sys
import threading
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path

from .cli.args import EXIT_USAGE

__all__ = ["run_in_workers", "cost"]

POLL = 0.2  #: seconds between two looks of the parent at its Ctrl-C flag


@dataclass
class Finished:
    """What a worker sends back for one scenario (its files are already written)."""

    name: str
    status: int            # 0, or 128 + a signal: interrupted
    stdout: str = ""
    stderr: str = ""
    error: str | None = None   # the message of a user-level error (ParameterError, SimulationError, OutputError)
    started: bool = True


def cost(name: str, settings: dict | None = None) -> float:
    """Estimated cost of a run: its number of communication steps (``ship``: 50 000; not their cost)."""
    from .scenarios import get
    scenario, settings = get(name), settings or {}
    stop_time = settings.get("stop_time") or scenario.stop_time
    return stop_time / (settings.get("step") or scenario.step)


# ----------------------------------------------------------------------------- worker side
_STOP = None  #: the worker's StopRequest (own SIGINT or the parent's shared flag)


def _start_worker(flag, parent: int) -> None:
    global _STOP
    from .cli.stopping import StopRequest
    from .orphans import die_with_parent
    die_with_parent(parent)                   # a parent killed with SIGKILL takes its workers along
    _STOP = StopRequest(quiet=True, shared=flag).__enter__()


def _job(out: Path, build_dir: Path, name: str, settings: dict | None) -> Finished:
    from obsfmu.observers.checks import ParameterError

    from .cli.runs import run_one
    from .master import SimulationError
    from .output import OutputError

    if _STOP():
        return Finished(name, _STOP.exit_code, started=False)
    stdout, stderr = io.StringIO(), io.StringIO()
    status, error = 0, None
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        try:
            status = run_one(out, build_dir, name, _STOP, settings)
        except (ParameterError, SimulationError, OutputError) as exc:
            error = str(exc)
    return Finished(name, status, stdout.getvalue(), stderr.getvalue(), error)


# ----------------------------------------------------------------------------- parent side
@contextlib.contextmanager
def _sigint_ignored():
    """Processes started inside inherit SIGINT ignored (Python then installs no KeyboardInterrupt)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _show(finished: Finished | None) -> None:
    if finished is None or not finished.started:
        return
    sys.stdout.write(finished.stdout)
    sys.stdout.flush()
    sys.stderr.write(finished.stderr)
    sys.stderr.flush()


def run_in_workers(out: Path, build_dir: Path, names: list[str], stop, jobs: int,
                   settings: dict[str, dict]) -> int:
    """Run ``names`` (settings per name for :func:`fmus.scenarios.run`, default: the scenario's) into
    ``out`` in ``jobs`` spawned processes; 0, 2 (a scenario failed) or 128 + a signal (interrupted)."""
    context = multiprocessing.get_context("spawn")
    flag = context.RawValue("b", 0)
    longest_first = sorted(names, key=lambda name: -cost(name, settings.get(name)))
    workers = min(jobs, len(names))
    print(f"obsfmu: running {len(names)} scenarios in {workers} worker processes, the most communication "
          f"steps first ({longest_first[0]})", file=sys.stderr, flush=True)
    results: dict[str, Finished | None] = {}
    crashed: dict[str, BaseException] = {}
    shown = 0
    with _sigint_ignored():
        pool = futures.ProcessPoolExecutor(workers, mp_context=context, initializer=_start_worker,
                                           initargs=(flag, os.getpid()))
        pending = {pool.submit(_job, out, build_dir, name, settings.get(name)): name for name in longest_first}
    try:
        while pending:
            done, _ = futures.wait(pending, timeout=POLL, return_when=futures.FIRST_COMPLETED)
            for future in done:
                name = pending.pop(future)
                try:
                    results[name] = future.result()
                except BrokenProcessPool as exc:
                    results[name] = Finished(name, 0, error=f"its worker process died ({exc})")
                except Exception as exc:  # noqa: BLE001  re-raised below, after the others finished
                    results[name], crashed[name] = None, exc
            if stop() and not flag.value:
                flag.value = 1
                for future in [f for f in pending if f.cancel()]:
                    results[pending.pop(future)] = None
            while shown < len(names) and names[shown] in results:
                _show(results[names[shown]])
                shown += 1
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    return _status(names, results, crashed, stop)


def _status(names, results: dict[str, Finished | None], crashed: dict[str, BaseException], stop) -> int:
    """0; 128 + the signal if a scenario was interrupted or not started (the parent's, else a worker's);
    2 if one failed (named on stderr); an unexpected exception of a worker is re-raised (with the
    worker's traceback)."""
    errors = [(name, results[name].error) for name in names if results.get(name) and results[name].error]
    for name, error in errors:
        print(f"obsfmu: error: {name}: {error}", file=sys.stderr)
    if crashed:
        name, exc = next(iter(crashed.items()))
        print(f"obsfmu: scenario {name} failed:", file=sys.stderr)
        raise exc
    if any(result is None or result.status for result in results.values()):
        signalled = [result.status for result in results.values() if result and result.status]
        return stop.exit_code if stop.requested or not signalled else signalled[0]
    return EXIT_USAGE if errors else 0
