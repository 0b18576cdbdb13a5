"""Campaigns on a real dask.distributed LocalCluster (two worker processes, one cluster for the module).

* the rows equal the same samples run one by one through ``obsfmu run`` (fresh process state, fresh FMUs),
  although the workers reuse their instantiated FMUs (``fmi2Reset``) across samples;
* faults are rows: an FMU error (invalid observer gain) and the per-sample time limit;
* resume: ``obsfmu sweep`` interrupted (SIGINT) keeps its finished samples, the same command computes
  only the missing ones and the table is complete;
* a worker process killed in the middle of a campaign costs no sample.

Short runs: ``ltv-ls-bounded`` for 0.3-1 s of model time (1e-3 s steps); the tests that need samples that last
(a time limit, an interrupt, a killed worker) run it longer: with its compiled kernels 10 s of model time take 0.1 s.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import distributed
import pytest

from obsfmu.fmus.cli import main as cli
from obsfmu.fmus.campaign.design import Campaign
from obsfmu.fmus.campaign.runner import local_cluster, run_campaign
from obsfmu.fmus.campaign.store import load_rows
from obsfmu.fmus.result import Result
from obsfmu.fmus.scenarios import get

OBSFMU = [sys.executable, "-m", "obsfmu"]


@pytest.fixture(scope="module")
def client():
    with local_cluster(2) as cluster, distributed.Client(cluster) as connected:
        yield connected


def _ltv(build_dir, vary, **kwargs):
    return Campaign("ltv-ls-bounded", vary=vary, build_dir=build_dir, **kwargs)


def test_rows_equal_obsfmu_run_of_each_sample(client, build_dir, tmp_path, capsys):
    campaign = _ltv(build_dir, {"plant.k[1]": "uniform(-4, -2)", "plant.x0[1]": "normal(2, 0.5)",
                                "observer.gamma": "[500, 1000]"}, samples=2, seed=11, stop_time=0.5)
    table = run_campaign(campaign, client=client, out=tmp_path / "sweep")
    rows = table.to_pylist()
    assert len(rows) == 4 and all(row["status"] == "ok" for row in rows)
    assert max(row["run_in_session"] for row in rows) > 1      # some samples ran on reset, reused instances
    assert all(row["worker"].split(":")[1] != str(os.getpid()) for row in rows)   # in the worker processes
    summarize = get("ltv-ls-bounded").summarize
    for k, row in enumerate(rows):
        csv = tmp_path / f"run{k}.csv"
        settings = [f"--set={name}={row[name]!r}" for name in ("plant.k[1]", "plant.x0[1]", "observer.gamma")]
        assert cli.main(["run", "ltv-ls-bounded", "--stop-time", "0.5", "--build-dir", str(build_dir), "--csv",
                         str(csv), *settings]) == 0
        metrics = summarize(Result.from_csv(csv)).metrics
        assert metrics, "the scenario reports metrics"
        assert {name: row[name] for name in metrics} == metrics, f"sample {k} differs from obsfmu run"
    capsys.readouterr()
    csv_rows = (tmp_path / "sweep" / "samples.csv").read_text().splitlines()
    assert len(csv_rows) == 5 and csv_rows[0].startswith('"sample_id","plant.k[1]","plant.x0[1]","observer.gamma"')


def test_an_fmu_error_and_the_time_limit_are_rows_with_their_reason(client, build_dir):
    errors = run_campaign(_ltv(build_dir, {"observer.gamma": "[1000, -1, 500]"}, stop_time=0.3), client=client)
    status = {row["observer.gamma"]: row for row in errors.to_pylist()}
    assert status[1000.0]["status"] == status[500.0]["status"] == "ok"
    assert status[-1.0]["status"] == "error" and not status[-1.0]["converged"]
    assert "gamma: must be > 0, got -1" in status[-1.0]["reason"]
    slow = run_campaign(_ltv(build_dir, {"observer.gamma": "[1000, 500]"}, stop_time=1000.0, time_limit=0.2),
                        client=client).to_pylist()
    assert [row["status"] for row in slow] == ["timeout", "timeout"]
    assert all("exceeded the time limit of 0.2 s" in row["reason"] and row["t_end"] < 1000.0 for row in slow)


def _wait_for(condition, timeout: float, what: str):
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.02)


def test_an_interrupted_sweep_resumes_with_only_the_missing_samples(client, build_dir, tmp_path):
    out = tmp_path / "resume"
    # 40 samples of 10 000 steps (~0.3 s each with the compiled kernels): the interrupt comes after the first stored
    # sample and well before the last
    count = 40
    command = OBSFMU + ["sweep", "ltv-ls-bounded", "--vary", f"plant.k[1]=-4:-2:{count}", "--stop-time", "10",
                        "--step", "1e-3", "--scheduler", client.scheduler.address, "--out", str(out), "--build-dir", str(build_dir),
                        "--no-plots"]
    # Ctrl-C as in a terminal, also when the tests run with SIGINT ignored (a shell's background job):
    # Python inherits an ignored SIGINT and then raises no KeyboardInterrupt
    first = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             cwd=Path(__file__).resolve().parents[3],
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    _wait_for(lambda: list((out / "samples").glob("part-*.parquet")) or first.poll() is not None, 120,
              "the first stored samples")
    first.send_signal(signal.SIGINT)
    stdout, stderr = first.communicate(timeout=120)
    assert first.returncode == 130, stderr
    assert "interrupted: every finished sample is in" in stderr
    kept = {row["sample_id"]: row for row in load_rows(out).to_pylist()}
    assert 0 < len(kept) < count and all(row["status"] == "ok" for row in kept.values())

    second = subprocess.run(command, capture_output=True, text=True, timeout=300,
                            cwd=Path(__file__).resolve().parents[3])
    assert second.returncode == 0, second.stderr
    assert f"{len(kept)} of {count} samples already stored; computing {count - len(kept)}" in second.stderr
    rows = load_rows(out).to_pylist()
    assert len(rows) == count and all(row["status"] == "ok" for row in rows)
    invocations = {row["invocation"] for row in rows if row["sample_id"] not in kept}
    assert len(invocations) == 1 and not invocations & {row["invocation"] for row in kept.values()}
    for row in rows:                                   # the samples of the first run were not computed again
        if row["sample_id"] in kept:
            assert row == kept[row["sample_id"]]
    table = (out / "samples.csv").read_text().splitlines()
    k1 = sorted(float(line.split(",")[1]) for line in table[1:])
    assert len(table) == count + 1 and k1 == pytest.approx([-4 + 2 * i / (count - 1) for i in range(count)], abs=1e-15)
    assert f"ltv-ls-bounded: {count} of {count} samples done ({count} ok)" in second.stdout


def test_a_killed_worker_process_costs_no_sample(client, build_dir, tmp_path):
    killed = []

    def kill_a_busy_worker(row):
        if killed:
            return
        busy = [address for address, keys in client.processing().items() if keys]
        if busy:
            pid = client.run(os.getpid, workers=busy[:1])[busy[0]]
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

    # samples long enough (~0.3 s each with the compiled kernels) that the first row comes while the others run
    campaign = _ltv(build_dir, {"plant.k[1]": "-4:-2:8"}, stop_time=100.0)
    table = run_campaign(campaign, client=client, out=tmp_path / "killed", on_row=kill_a_busy_worker)
    assert killed, "a worker was busy when the first row arrived"
    rows = table.to_pylist()
    assert len(rows) == 8 and len({row["sample_id"] for row in rows}) == 8
    assert all(row["status"] == "ok" for row in rows), [row["reason"] for row in rows]
    # a new worker process imports distributed and the project: seconds alone, over a minute on a loaded machine
    _wait_for(lambda: len(client.scheduler_info()["workers"]) == 2, 240, "the nanny to restart the worker")


def test_the_default_local_cluster_runs_a_campaign_with_a_progress_bar(build_dir, tmp_path, capfd):
    campaign = Campaign("discrete-gpebo", vary={"source.amplitude[1]": "[0.5, 1.5]"}, build_dir=build_dir)
    table = run_campaign(campaign, workers=1, out=tmp_path, progress=True)
    assert table.num_rows == 2 and table["converged"].to_pylist() == [True, True]
    assert "2/2 samples  0 failed" in capfd.readouterr().err
