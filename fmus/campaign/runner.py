"""Running a campaign on Dask: a LocalCluster of worker processes, or an existing scheduler.

:func:`run_campaign` plans the campaign, skips the samples already in
``OUT/samples`` (same id, same FMUs), submits the others as tasks of
:func:`~fmus.campaign.worker.run_sample`, stores each batch of finished rows
as soon as it arrives, and at the end compacts the dataset, writes
``OUT/samples.csv``, ``OUT/summary.txt`` and the figures, and returns the
campaign's table.

Addresses: the LocalCluster's scheduler, workers and nannies listen on 127.0.0.1 only, and so does
its HTTP server (the dashboard, ``/status``, on a free port) unless ``dashboard`` asks for another
address (``obsfmu sweep --dashboard HOST:PORT``; ``0.0.0.0:8787`` opens it to the network).

Lost workers: the scheduler reschedules the tasks of a worker that died
(up to ``allowed-failures`` times per task, then the task is a row with
status ``crashed``); a task that raised unexpectedly is retried
(``retries``).  The tasks are pure functions of their inputs, so a rerun
gives the same row.
"""

from __future__ import annotations

import json
import logging
import os
import socket
import sys
import time
import uuid
from contextlib import ExitStack, contextmanager, nullcontext
from datetime import datetime, timezone
from pathlib import Path

import pyarrow as pa

from .design import Campaign, Plan
from .errors import CampaignError
from .plots import write_plots
from .progress import Progress
from .store import Store, rows_to_table
from .table import campaign_table, measured, stop_in_time_unit, summary_text
from .worker import FmuPlugin, ParentWatch, Task, plugin_name, run_sample

__all__ = ["run_campaign", "local_cluster", "default_workers", "ALLOWED_FAILURES", "RETRIES", "LOCALHOST"]

LOCALHOST = "127.0.0.1"  #: the only interface the local cluster listens on, unless a dashboard address is given
ALLOWED_FAILURES = 3   #: a task may lose this many workers before it is recorded as "crashed"
RETRIES = 2            #: retries of a task that raised (run_sample catches the sample's own failures)


def default_workers() -> int:
    """The cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def max_workers() -> int:
    """The most worker processes of a LocalCluster: 4 per CPU (a million were accepted and ran out of memory)."""
    return 4 * (os.cpu_count() or 1)


#: seconds to wait for a scheduler's first answer
SCHEDULER_TIMEOUT = 10.0


def check_scheduler(address: str) -> None:
    """A :class:`CampaignError` naming ``--scheduler`` unless ``address`` answers as a Dask scheduler does: on a
    new connection it sends its handshake at once, a frame whose first 8 bytes are its length (little-endian).
    Nothing is sent to it.  (An HTTP server at that port waits for a request: Dask then hung, or read the
    server's reply as a frame length and asked for 3 EiB.)"""
    from urllib.parse import urlsplit

    parts = urlsplit(address if "://" in address else "tcp://" + address)
    try:
        port = parts.port
    except ValueError:
        port = None
    if parts.scheme != "tcp" or not parts.hostname or port is None:
        raise CampaignError(f"--scheduler: {address!r} is not a scheduler address (tcp://HOST:PORT)")
    try:
        with socket.create_connection((parts.hostname, port), timeout=SCHEDULER_TIMEOUT) as connection:
            connection.settimeout(SCHEDULER_TIMEOUT)
            first = b""
            while len(first) < 8:
                more = connection.recv(8 - len(first))
                if not more:
                    break
                first += more
    except socket.timeout:
        raise CampaignError(f"--scheduler: {address} sent no Dask handshake within {SCHEDULER_TIMEOUT:g} s: not a "
                            f"Dask scheduler (its port is usually 8786; the dashboard's 8787 is HTTP)") from None
    except OSError as exc:
        raise CampaignError(f"--scheduler: cannot connect to {address}: {exc.strerror or exc}") from None
    if len(first) < 8 or not 0 < int.from_bytes(first, "little") < 2 ** 20:
        raise CampaignError(f"--scheduler: {address} does not speak Dask's protocol (not a Dask scheduler)")


@contextmanager
def _client(workers: int | None, scheduler: str | None, client, dashboard: str | None = None, log=None):
    """A dask client: the given one, one connected to ``scheduler``, or a new LocalCluster's (its dashboard
    at ``dashboard``, announced through ``log``)."""
    if client is not None:
        yield client
        return
    from distributed import Client

    if scheduler:
        with Client(scheduler) as connected:
            yield connected
        return
    with local_cluster(workers or default_workers(), dashboard) as cluster, Client(cluster) as local:
        local.register_plugin(ParentWatch(os.getpid()))      # workers die with this process, SIGKILL too
        if dashboard and log:
            log(f"dashboard: {_dashboard_link(cluster, dashboard)}")
        yield local


def _dashboard_link(cluster, dashboard: str) -> str:
    """The dashboard's URL: the host asked for (Dask's link names the scheduler's), the port it got."""
    from urllib.parse import urlsplit

    host = dashboard.rpartition(":")[0] or socket.gethostname()
    return f"http://{host}:{urlsplit(cluster.dashboard_link).port}/status"


def local_cluster(workers: int, dashboard: str | None = None):
    """A LocalCluster of ``workers`` single-threaded worker processes (each keeps its own Sessions), quiet
    logs, ``ALLOWED_FAILURES`` lost workers allowed per task; everything listens on ``LOCALHOST`` only,
    the HTTP server (dashboard) on a free port there, or at ``dashboard`` (``HOST:PORT``) if given."""
    import dask
    from distributed import LocalCluster

    with dask.config.set({"distributed.scheduler.allowed-failures": ALLOWED_FAILURES}):
        return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host=LOCALHOST,
                            dashboard_address=dashboard or f"{LOCALHOST}:0", worker_dashboard_address=None,
                            silence_logs=logging.ERROR)


def _tasks(plan: Plan, samples) -> list[Task]:
    fixed: dict[str, dict[str, float]] = {}
    for name, value in plan.campaign.fixed.items():
        instance, _, variable = name.partition(".")
        fixed.setdefault(instance, {})[variable] = value
    tasks = []
    for sample in samples:
        start = {instance: dict(values) for instance, values in fixed.items()}
        for name, value in sample.values.items():
            instance, _, variable = name.partition(".")
            start.setdefault(instance, {})[variable] = value
        tasks.append(Task(sample.id, plan.campaign.scenario, plan.fmu_set, dict(plan.settings), start,  # name or path
                          dict(sample.values), float(plan.campaign.time_limit)))
    return tasks


def _manifest(plan: Plan) -> dict:
    campaign = plan.campaign
    return {"scenario": plan.scenario.name, "settings": plan.settings,
            "vary": {name: str(spec) for name, spec in campaign.specs.items()},
            "samples": campaign.samples, "seed": campaign.seed, "set": campaign.fixed,
            "time_limit": campaign.time_limit, "fmu_set": plan.fmu_set, "sample_count": len(plan.samples),
            "measure": {"convergence_time": list(plan.measure.time), "final_error": list(plan.measure.error),
                        "time_label": plan.measure.time_label, "error_label": plan.measure.error_label,
                        "time_unit": plan.time_unit}}


def _pending(plan: Plan, stored: pa.Table | None, retry_failed: bool, log) -> list:
    """The samples without a stored row computed with the plan's FMUs (or only a failed one, to retry)."""
    done, stale = set(), set()
    if stored is not None:
        for row in stored.select(["sample_id", "status", "fmu_set"]).to_pylist():
            if row["fmu_set"] != plan.fmu_set:
                stale.add(row["sample_id"])
            elif row["status"] == "ok" or not retry_failed:
                done.add(row["sample_id"])
    pending = [sample for sample in plan.samples if sample.id not in done]
    if done:
        log(f"{len(plan.samples) - len(pending)} of {len(plan.samples)} samples already stored; "
            f"computing {len(pending)}")
    again = sum(sample.id in stale for sample in pending)
    if again:
        log(f"{again} stored samples were computed with other FMUs (rebuilt since): computing them again")
    return pending


def run_campaign(campaign: Campaign | Plan, *, workers: int | None = None, scheduler: str | None = None,
                 client=None, out: Path | str | None = None, progress: bool | None = None,
                 retry_failed: bool = False, report_only: bool = False, plots: bool = True, on_row=None,
                 log=None, dashboard: str | None = None) -> pa.Table:
    """Run ``campaign`` (or its plan) and return its table (one row per sample, in sample order).

    Parameters
    ----------
    workers : int, optional
        Worker processes of the LocalCluster (default: the machine's cores).
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:8786``) instead of a LocalCluster.
    client : distributed.Client, optional
        An existing client to use (neither ``workers`` nor ``scheduler`` then).
    out : path, optional
        Campaign directory: ``samples/`` (Parquet dataset), ``samples.csv``, ``summary.txt``,
        ``campaign.json``, figures.  Samples already stored there are not computed again.
        ``None``: nothing is written and nothing is resumed.
    progress : bool, optional
        Progress bar on stderr (default: when stderr is a terminal).
    retry_failed : bool
        Also recompute stored samples whose status is not ``ok``.
    report_only : bool
        Compute nothing: the table, summary and figures of the rows stored in ``out``, also rows
        computed with other FMUs (e.g. rebuilt since, after a change of the project's code).
    on_row : callable, optional
        Called with each new row once it is stored (e.g. for live monitoring).
    log : callable, optional
        Receives one-line notes (default: print to stderr).
    dashboard : str, optional
        ``HOST:PORT`` of the LocalCluster's dashboard (default: 127.0.0.1 on a free port, not announced;
        ``0.0.0.0:8787`` serves it to the network).  Only with a LocalCluster.
    """
    log = log or (lambda text: print(text, file=sys.stderr))
    if sum(x is not None for x in (workers, scheduler, client)) > 1:
        raise CampaignError("workers, scheduler, client: give at most one")
    if dashboard and (scheduler or client is not None):
        raise CampaignError("dashboard: only for the local cluster; an existing scheduler serves its own")
    if report_only and out is None:
        raise CampaignError("report_only: needs the campaign directory (out)")
    if workers is not None and not 1 <= workers <= max_workers():
        raise CampaignError(f"--workers: {workers} worker processes on {os.cpu_count() or 1} CPUs; at most "
                            f"{max_workers()} (4 per CPU; each is a Python process of 100+ MB)")
    if scheduler is not None:
        check_scheduler(scheduler)               # before anything is written
    plan = campaign if isinstance(campaign, Plan) else campaign.plan()
    store = Store(out) if out is not None else None
    with store.locked() if store else nullcontext():      # one sweep at a time per --out
        return _run(plan, store, report_only, retry_failed, progress, workers, scheduler, client, dashboard, log,
                    plots, on_row)


def _run(plan: Plan, store: Store | None, report_only, retry_failed, progress, workers, scheduler, client,
         dashboard, log, plots, on_row) -> pa.Table:
    memory: list[dict] = []
    if store:
        store.write_text("campaign.json", json.dumps(_manifest(plan), indent=2) + "\n")
    pending = [] if report_only else _pending(plan, store.read() if store else None, retry_failed, log)
    if pending:
        before = len(plan.samples) - len(pending)
        bar = Progress(len(plan.samples), before, sys.stderr.isatty() if progress is None else progress)
        try:
            _compute(plan, _tasks(plan, pending), _client(workers, scheduler, client, dashboard, log), store,
                     memory, bar, on_row)
        finally:
            bar.close()
    if store is None:
        return campaign_table(plan, rows_to_table(memory) if memory else None)
    store.compact()
    table = campaign_table(plan, store.read(), any_fmus=report_only)
    _report(plan, store, table, plots, report_only, log)
    return table


def _report(plan: Plan, store: Store, table: pa.Table, plots: bool, report_only: bool, log) -> None:
    """CSV, summary.txt and figures of the campaign's table."""
    if report_only:
        log(f"report only: {table.num_rows} of {len(plan.samples)} samples are stored in {store.directory}")
        stale = sum(fmu_set != plan.fmu_set for fmu_set in table["fmu_set"].to_pylist()) if table.num_rows else 0
        if stale:
            log(f"{stale} of the {table.num_rows} rows were computed with other FMUs than the current ones "
                f"({plan.fmu_set}); run without --report-only to compute them again")
    store.write_csv(table)
    store.write_text("summary.txt", summary_text(plan, table) + "\n")
    if plots:
        write_plots(plan, table, store.out)


def _compute(plan: Plan, tasks: list[Task], connection, store: Store | None, memory: list, bar: Progress,
             on_row) -> None:
    """Submit the tasks, store every batch of finished rows as it arrives."""
    from distributed import as_completed

    invocation = uuid.uuid4().hex[:12]
    with ExitStack() as stack:
        dask_client = stack.enter_context(connection)
        files = {model: Path(path).read_bytes() for model, path in plan.fmus.items()}
        dask_client.register_plugin(FmuPlugin(plan.fmu_set, files))
        stack.callback(_unregister, dask_client, plugin_name(plan.fmu_set))
        futures = {}
        for task in tasks:
            future = dask_client.submit(run_sample, task, key=f"obsfmu-sample-{task.sample_id}-{invocation}",
                                        pure=False, retries=RETRIES)
            futures[future.key] = (future, task)
        try:
            for batch in _batches(as_completed([f for f, _ in futures.values()]), bar):
                rows = [_row(future, futures[future.key][1], invocation) for future in batch]
                try:   # a metric the measure names but the scenario does not report stops the campaign
                    rows = [measured(row, plan.measure, stop_in_time_unit(plan)) for row in rows]
                finally:
                    if store:
                        store.append(rows)
                    else:
                        memory.extend(rows)
                bar.update(done=len(rows), failed=sum(row["status"] != "ok" for row in rows))
                for future in batch:
                    futures.pop(future.key)
                    future.release()
                for row in rows:
                    if on_row:
                        on_row(row)
        finally:
            for future, _ in futures.values():   # interrupted: do not leave work behind on a shared cluster
                future.cancel()


def _batches(completed, bar: Progress, poll: float = 0.2):
    """The finished futures, batch by batch; the progress bar (elapsed, ETA) is redrawn while waiting."""
    while not completed.is_empty():
        batch = completed.next_batch(block=False)
        if batch:
            yield batch
        else:
            bar.update()
            time.sleep(poll)


def _row(future, task: Task, invocation: str) -> dict:
    """The task's row, or a ``crashed`` row when the task itself failed (lost workers, retries exhausted)."""
    try:
        row = future.result()
    except Exception as exc:   # noqa: BLE001 -- KilledWorker and the like are data too
        row = {"sample_id": task.sample_id, **task.inputs, "status": "crashed",
               "reason": f"{type(exc).__name__}: {exc}"[:2000], "fmu_set": task.fmu_set}
    row["invocation"] = invocation
    row["finished_at"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
    return row


def _unregister(client, name: str) -> None:
    try:
        client.unregister_worker_plugin(name)
    except Exception:   # noqa: BLE001 -- the cluster may be gone already (interrupt)
        pass
