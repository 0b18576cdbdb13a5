"""Worker processes die with their parent, SIGKILL included (fmus/orphans.py; issue 37: after `kill -9` of
`obsfmu report --jobs 2` both workers and the resource tracker ran on under PID 1, writing for 22-26 s)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")


def _stat(pid: int) -> tuple[str, int] | None:
    """(state, parent pid) of ``pid``, or None if it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text.rpartition(")")[2].split()
    return fields[0], int(fields[1])


def _children(parent: int) -> set[int]:
    found = set()
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            stat = _stat(int(entry.name))
            if stat and stat[1] == parent:
                found.add(int(entry.name))
    return found


def _alive(pid: int) -> bool:
    stat = _stat(pid)
    return stat is not None and stat[0] not in "ZX"     # a zombie is dead (PID 1 may never reap it)


def _kill_parent_once_it_has(command: list[str], workers: int, cwd: Path) -> set[int]:
    """Start ``command``, SIGKILL it once it has ``workers`` child processes; its children then."""
    process = subprocess.Popen(command, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while len(children := _children(process.pid)) < workers:
            assert process.poll() is None, "the command ended before its workers started"
            assert time.monotonic() < deadline, "no workers within 120 s"
            time.sleep(0.05)
        time.sleep(0.5)                                   # the workers are running samples now
        children = _children(process.pid)
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
    return children


def _gone_within(pids: set[int], seconds: float) -> set[int]:
    deadline = time.monotonic() + seconds
    while (alive := {pid for pid in pids if _alive(pid)}) and time.monotonic() < deadline:
        time.sleep(0.1)
    return alive


def _obsfmu(*args) -> list[str]:
    return [sys.executable, "-m", "obsfmu", *map(str, args)]


def test_the_workers_of_a_killed_report_die_with_it(every_fmu, build_dir, tmp_path):
    children = _kill_parent_once_it_has(_obsfmu("report", "--jobs", 2, "--out", tmp_path / "out",
                                                "--build-dir", build_dir), 2, tmp_path)
    left = _gone_within(children, 10.0)
    for pid in left:
        os.kill(pid, signal.SIGKILL)
    assert not left, f"still running 10 s after their parent was killed: {sorted(left)}"


def test_the_workers_of_a_killed_sweep_die_with_it(ship_fmus, build_dir, tmp_path):
    """A LocalCluster's workers also lose their in-process nanny's connection and close (measured: within
    10 s without fmus.campaign.worker.ParentWatch too); the plugin ends them at once."""
    children = _kill_parent_once_it_has(_obsfmu("sweep", "ship", "--vary", "observer.x_hat0[1]=0:1:40",
                                                "--workers", 2, "--out", tmp_path / "sweep",
                                                "--build-dir", build_dir), 2, tmp_path)
    left = _gone_within(children, 10.0)
    for pid in left:
        os.kill(pid, signal.SIGKILL)
    assert not left, f"still running 10 s after their parent was killed: {sorted(left)}"
