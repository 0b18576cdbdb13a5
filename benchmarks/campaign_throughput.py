"""Campaign throughput on a LocalCluster with 1 and 2 worker processes, and the cost of one sample
against one ``obsfmu run`` of the same case.

Measured in one run:

* ``obsfmu run SCENARIO --stop-time T --set ...`` as a fresh process (interpreter start, imports, FMU
  extraction and instantiation, the run, the summary), wall time;
* the same case inside a campaign: a worker runs it on its cached Session (``fmi2Reset`` + start values),
  the row's ``wall_time`` (run + summary) -- and the one-off ``setup_time`` of a worker's first sample;
* the whole campaign of ``--samples`` samples (a grid over ``plant.k[1]``) with 1 and with 2 workers
  (cluster start-up timed separately), samples per second and the speed-up.

The load average before and after is printed, and how busy the workers were (their CPU time over
workers x wall time): on a shared machine other processes take the cores too, and a speed-up below 2
with workers far from 100 % busy is the machine's, not the campaign's.

    .venv/bin/python benchmarks/campaign_throughput.py [--scenario ltv-ls-bounded] [--stop-time 4]
                                                       [--samples 12] [--workers 1 2]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from distributed import Client

from obsfmu.fmus.campaign.design import Campaign
from obsfmu.fmus.campaign.runner import local_cluster, run_campaign


def single_run(scenario: str, stop_time: float, build_dir: Path, values: dict[str, float]) -> float:
    """Wall time of ``obsfmu run`` of one case in a fresh process."""
    command = [sys.executable, "-m", "obsfmu", "run", scenario, "--stop-time", repr(stop_time),
               "--build-dir", str(build_dir)] + [f"--set={name}={value!r}" for name, value in values.items()]
    started = time.perf_counter()
    subprocess.run(command, check=True, capture_output=True, cwd=Path(__file__).resolve().parents[1])
    return time.perf_counter() - started


def campaign(plan, workers: int) -> dict:
    started = time.perf_counter()
    with local_cluster(workers) as cluster, Client(cluster) as client:
        ready = time.perf_counter()
        table = run_campaign(plan, client=client, progress=False)
        finished = time.perf_counter()
    rows = table.to_pylist()
    assert all(row["status"] == "ok" for row in rows), [row["reason"] for row in rows]
    steady = [row["wall_time"] for row in rows if row["run_in_session"] > 1]
    cpu = sum(row["cpu_time"] for row in rows)
    return {"cluster": ready - started, "campaign": finished - ready, "rows": rows,
            "busy": cpu / (workers * (finished - ready)), "cpu": statistics.median(row["cpu_time"] for row in rows),
            "steady": statistics.median(steady) if steady else float("nan"),
            "setup": statistics.median(row["setup_time"] for row in rows if row["run_in_session"] == 1)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="ltv-ls-bounded")
    parser.add_argument("--stop-time", type=float, default=4.0)
    parser.add_argument("--samples", type=int, default=12)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--build-dir", default=None)
    args = parser.parse_args()
    build_dir = Path(args.build_dir or tempfile.mkdtemp(prefix="obsfmu_bench_"))
    plan = Campaign(args.scenario, vary={"plant.k[1]": f"-3.5:-2.5:{args.samples}"}, stop_time=args.stop_time,
                    build_dir=build_dir).plan()
    load_before = os.getloadavg()
    single = single_run(args.scenario, args.stop_time, build_dir, plan.samples[0].values)
    results = {n: campaign(plan, n) for n in args.workers}
    load_after = os.getloadavg()

    print(f"{args.scenario}, stop time {args.stop_time:g}, {len(plan.samples)} samples (grid over plant.k[1]); "
          f"{os.cpu_count()} cores; load average before {load_before[0]:.2f}, after {load_after[0]:.2f}")
    print(f"one 'obsfmu run' of the first case (fresh process):        {single:7.2f} s")
    for n, r in results.items():
        per_sample = r["campaign"] / len(plan.samples)
        print(f"{n} worker(s): cluster start {r['cluster']:5.2f} s, campaign {r['campaign']:6.2f} s -> "
              f"{len(plan.samples) / r['campaign']:.3f} samples/s, {per_sample:.2f} s per sample "
              f"(reused session: median {r['steady']:.2f} s per run, {r['cpu']:.2f} s CPU; first sample's "
              f"set-up {r['setup']:.2f} s); the workers' CPU time is {100 * r['busy']:.0f} % of workers x wall time")
    if len(results) >= 2:
        one, two = results[args.workers[0]]["campaign"], results[args.workers[1]]["campaign"]
        print(f"speed-up {args.workers[0]} -> {args.workers[1]} workers: {one / two:.2f}x")
    first = min(results)
    print(f"cost per sample in a campaign ({first} worker): {results[first]['steady']:.2f} s vs "
          f"{single:.2f} s for one 'obsfmu run' ({single / results[first]['steady']:.2f}x)")


if __name__ == "__main__":
    main()
