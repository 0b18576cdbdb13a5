"""What runs on a Dask worker: one sample -> one row, on a Session reused across samples.

The FMUs reach the workers through a worker plugin (:class:`FmuPlugin`):
the scheduler keeps it and installs it on every worker, including workers
that join or are restarted later, so a worker on another machine needs no
shared file system.  Each worker process (each of its threads) keeps one
:class:`fmus.master.Session` per (scenario, FMU set): the FMUs are extracted
and instantiated once and every later sample is ``fmi2Reset`` + its start
values.  A run that fails discards the session (the next sample gets a
fresh one), so one broken instance never leaks into another sample.

:func:`run_sample` never raises for a sample's own failure: an FMU error
(:class:`~fmus.master.SimulationError`), a summary that cannot be computed
or the per-sample time limit become the row's ``status`` and ``reason``.
It has no side effects beyond the session cache, so Dask may run it again
(a retry after a lost worker) with the same result.
"""

from __future__ import annotations

import atexit
import os
import socket
import threading
import time as wallclock
import warnings
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

from distributed import WorkerPlugin

from .. import scenarios
from ..orphans import die_with_parent
from ..system import resolve
from ..master import Session, SimulationError

__all__ = ["Task", "FmuPlugin", "ParentWatch", "run_sample", "install_fmus", "STATUSES"]

#: row statuses: finished, FMU/summary error, over the time limit, worker lost too often (set by the client)
STATUSES = ("ok", "error", "timeout", "crashed")
MAX_SESSIONS = 4   #: sessions kept per process (least recently used are closed)

_FMU_DIRS: dict[str, Path] = {}
_SESSIONS: "OrderedDict[tuple, list]" = OrderedDict()   # key -> [Session, runs so far]
_LOCK = threading.Lock()


@dataclass(frozen=True)
class Task:
    """Everything one sample needs (small: sent with every task)."""

    sample_id: str
    scenario: str
    fmu_set: str
    settings: dict                       #: stop_time, step, order, coupling (, tolerance)
    start: dict[str, dict[str, float]]   #: per instance: the fixed and varied start values
    inputs: dict[str, float]             #: the varied values, "instance.variable" -> value
    time_limit: float                    #: seconds of wall time


class FmuPlugin(WorkerPlugin):
    """Writes one FMU set into the worker's local directory and registers it under its fingerprint."""

    idempotent = True

    def __init__(self, fmu_set: str, files: dict[str, bytes]):
        self.fmu_set = fmu_set
        self.files = files   #: model name -> .fmu bytes
        self.name = plugin_name(fmu_set)

    def setup(self, worker) -> None:
        install_fmus(self.fmu_set, self.files, Path(worker.local_directory))

    def teardown(self, worker) -> None:
        forget_fmus(self.fmu_set)


class ParentWatch(WorkerPlugin):
    """Ends a LocalCluster's worker process when the obsfmu process that started it dies, SIGKILL included
    (:func:`fmus.orphans.die_with_parent`).  A worker whose parent is another process (a cluster of its
    own, a nanny elsewhere) is left alone."""

    idempotent = True
    name = "obsfmu-parent-watch"

    def __init__(self, parent: int):
        self.parent = parent

    def setup(self, worker) -> None:
        if os.getppid() == self.parent:
            die_with_parent(self.parent)


def plugin_name(fmu_set: str) -> str:
    return f"obsfmu-fmus-{fmu_set}"


def install_fmus(fmu_set: str, files: dict[str, bytes], root: Path) -> Path:
    """Write ``files`` (model name -> bytes) to ``root/obsfmu-fmus-<fmu_set>/<model>.fmu``; idempotent."""
    directory = Path(root) / plugin_name(fmu_set)
    directory.mkdir(parents=True, exist_ok=True)
    for model, data in files.items():
        path = directory / f"{model}.fmu"
        if not path.exists() or path.stat().st_size != len(data):
            partial = directory / f".{model}.{os.getpid()}.partial"
            partial.write_bytes(data)
            os.replace(partial, path)
    with _LOCK:
        _FMU_DIRS[fmu_set] = directory
    return directory


def forget_fmus(fmu_set: str) -> None:
    """Close the sessions of ``fmu_set`` in this process and unregister it."""
    with _LOCK:
        _FMU_DIRS.pop(fmu_set, None)
        stale = [key for key in _SESSIONS if key[2] == fmu_set]
        closing = [_SESSIONS.pop(key)[0] for key in stale]
    for session in closing:
        session.close()


@atexit.register
def _close_all() -> None:
    with _LOCK:
        closing = [entry[0] for entry in _SESSIONS.values()]
        _SESSIONS.clear()
    for session in closing:
        session.close()


def _session(task: Task) -> tuple[Session, int, float]:
    """The cached session of this thread for the task's scenario and FMUs: (session, run number, setup time)."""
    key = (threading.get_ident(), task.scenario, task.fmu_set)
    with _LOCK:
        entry = _SESSIONS.get(key)
        if entry is not None:
            _SESSIONS.move_to_end(key)
            entry[1] += 1
            return entry[0], entry[1], 0.0
        directory = _FMU_DIRS.get(task.fmu_set)
    if directory is None:
        raise SimulationError(f"FMU set {task.fmu_set} is not installed on this worker (the campaign registers "
                              f"it as the worker plugin {plugin_name(task.fmu_set)!r})")
    started = wallclock.perf_counter()
    scenario = resolve(task.scenario)          # a name, or a system file read in this worker
    fmus = {model: directory / f"{model}.fmu" for _, model, _ in scenario.components}
    session = Session(scenarios.system(scenario, fmus), echo_log=False)
    setup = wallclock.perf_counter() - started
    with _LOCK:
        _SESSIONS[key] = [session, 1]
        evicted = [_SESSIONS.popitem(last=False)[1][0] for _ in range(max(0, len(_SESSIONS) - MAX_SESSIONS))]
    for old in evicted:
        old.close()
    return session, 1, setup


def _discard(task: Task) -> None:
    with _LOCK:
        entry = _SESSIONS.pop((threading.get_ident(), task.scenario, task.fmu_set), None)
    if entry is not None:
        entry[0].close()


def run_sample(task: Task) -> dict:
    """Run one sample and return its row (inputs, status, reason, timings, the scenario's summary metrics)."""
    row = {"sample_id": task.sample_id, **task.inputs, "status": "ok", "reason": "", "t_end": float("nan"),
           "wall_time": float("nan"), "cpu_time": float("nan"), "setup_time": 0.0, "run_in_session": 0,
           "worker": f"{socket.gethostname()}:{os.getpid()}", "fmu_set": task.fmu_set, "warnings": ""}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            session, row["run_in_session"], row["setup_time"] = _session(task)
        except Exception as exc:   # noqa: BLE001 -- any failure is the sample's data
            return {**row, "status": "error", "reason": f"setting up the FMUs failed: {_text(exc)}"}
        started, cpu = wallclock.perf_counter(), wallclock.process_time()
        deadline = started + task.time_limit
        try:
            result = session.run(**task.settings, start=task.start,
                                 should_stop=lambda: wallclock.perf_counter() > deadline)
        except Exception as exc:   # noqa: BLE001
            _discard(task)
            row.update(status="error", reason=_text(exc))
        else:
            row["t_end"] = float(result.time[-1])
            if result.interrupted:
                row.update(status="timeout", reason=f"exceeded the time limit of {task.time_limit:g} s of wall "
                                                    f"time at t = {row['t_end']:.6g} of {task.settings['stop_time']:g}")
            else:
                row.update(_metrics(task, result, row))
        row["wall_time"] = wallclock.perf_counter() - started
        row["cpu_time"] = wallclock.process_time() - cpu
        row["warnings"] = " | ".join(dict.fromkeys(str(w.message) for w in caught))[:2000]
    return row


def _metrics(task: Task, result, row: dict) -> dict:
    """The scenario's summary metrics of a finished run (a metric named like a row column gets ``metric_``)."""
    summarize = resolve(task.scenario).summarize
    if summarize is None:
        return {}
    try:
        metrics = summarize(result).metrics
    except Exception as exc:   # noqa: BLE001
        return {"status": "error", "reason": f"the scenario's summary failed: {_text(exc)}"}
    return {(f"metric_{name}" if name in row else name): float(value) for name, value in metrics.items()}


def _text(exc: BaseException) -> str:
    name = "" if isinstance(exc, SimulationError) else f"{type(exc).__name__}: "
    return f"{name}{exc}"[:2000]
