"""Faults of the host side (issue 29): what the commands do to the machine and to their files.

* a sweep listens on 127.0.0.1 only (its scheduler, workers, nannies and dashboard), unless
  ``--dashboard`` asks for another address;
* SIGTERM and SIGHUP stop ``run``, ``all``, ``report`` and ``sweep`` as Ctrl-C does (rows kept in
  ``NAME.partial.csv``, no temporary file left, exit 128 + the signal);
* a full disk (a file-size limit) is one line naming the path, exit 2, no temporary file left,
  what was complete kept;
* ``report.html`` escapes every field of the results folder and embeds only figures inside it;
  every claim is marked met / not met with its numbers, every number says where it holds;
* config mistakes (a control character, a name with a newline, a huge plant) are one line, exit 2,
  nothing written.

Real ``obsfmu`` processes wherever a signal, a socket or a limit of the process is involved.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

from fmus.campaign.design import Campaign
from fmus.campaign.errors import CampaignError
from fmus.campaign.runner import run_campaign
from fmus.scenarios import ensure_fmus, get

OBSFMU = [sys.executable, "-m", "fmus.cli"]
ROOT = Path(__file__).resolve().parents[1]


def _start(args, **kwargs) -> subprocess.Popen:
    return subprocess.Popen(OBSFMU + [str(a) for a in args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=ROOT, **kwargs)


def _hidden(directory: Path) -> list[Path]:
    return [p for p in Path(directory).rglob(".*")]


# ----------------------------------------------------------------------------- 1: listening addresses
def _listening(process: psutil.Process) -> set[tuple[str, int]]:
    """The (address, port) pairs ``process`` and its children listen on (TCP)."""
    found = set()
    try:
        family = [process] + process.children(recursive=True)
    except psutil.NoSuchProcess:
        return found
    for member in family:
        try:
            found |= {(c.laddr.ip, c.laddr.port) for c in member.net_connections(kind="tcp")
                      if c.status == psutil.CONN_LISTEN}
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            pass
    return found


def _sweep_listening(build_dir, out: Path, *extra) -> tuple[set[tuple[str, int]], subprocess.CompletedProcess]:
    ensure_fmus(get("ltv-ls-bounded"), build_dir)
    process = _start(["sweep", "ltv-ls-bounded", "--vary", "plant.k[1]=-4:-2:3", "--stop-time", "1", "--workers", "1",
                      "--out", out, "--build-dir", build_dir, "--no-plots", *extra])
    watched, seen = psutil.Process(process.pid), set()
    deadline = time.monotonic() + 240
    while process.poll() is None and time.monotonic() < deadline:
        seen |= _listening(watched)
        time.sleep(0.05)
    stdout, stderr = process.communicate(timeout=60)
    return seen, subprocess.CompletedProcess(process.args, process.returncode, stdout, stderr)


def test_a_sweep_listens_on_localhost_only(build_dir, tmp_path):
    seen, done = _sweep_listening(build_dir, tmp_path / "sweep")
    assert done.returncode == 0, done.stderr
    assert len(seen) >= 3, seen                         # scheduler, its HTTP server, the worker (and nanny)
    assert {address for address, _ in seen} == {"127.0.0.1"}, seen
    assert "dashboard" not in done.stderr               # not announced unless asked for


def test_a_sweep_serves_its_dashboard_where_asked_and_only_there(build_dir, tmp_path):
    with socket.socket() as probe:        # a free port for the dashboard
        probe.bind(("127.0.0.2", 0))
        port = probe.getsockname()[1]
    seen, done = _sweep_listening(build_dir, tmp_path / "sweep", "--dashboard", f"127.0.0.2:{port}")
    assert done.returncode == 0, done.stderr
    assert ("127.0.0.2", port) in seen and {a for a, _ in seen} == {"127.0.0.1", "127.0.0.2"}, seen
    assert f"dashboard: http://127.0.0.2:{port}/status" in done.stderr


def test_a_dashboard_address_is_checked_and_needs_the_local_cluster():
    bad = subprocess.run(OBSFMU + ["sweep", "ship", "--vary", "plant.x0[1]=0:1:2", "--dashboard", "8787"],
                         capture_output=True, text=True, cwd=ROOT)
    assert bad.returncode == 2 and "--dashboard: '8787': expected HOST:PORT" in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1
    study = Campaign("ship", vary={"plant.x0[1]": "0:1:2"})
    with pytest.raises(CampaignError, match="dashboard: only for the local cluster"):
        run_campaign(study, scheduler="tcp://127.0.0.1:1", dashboard="127.0.0.1:8787")
