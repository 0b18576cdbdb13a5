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

from obsfmu.fmus.campaign.design import Campaign
from obsfmu.fmus.campaign.errors import CampaignError
from obsfmu.fmus.campaign.runner import run_campaign
from obsfmu.fmus.scenarios import ensure_fmus, get

OBSFMU = [sys.executable, "-m", "obsfmu"]
ROOT = Path(__file__).resolve().parents[2]


def _start(args, **kwargs) -> subprocess.Popen:
    return subprocess.Popen(OBSFMU + [str(a) for a in args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=ROOT, **kwargs)


def _hidden(directory: Path) -> list[Path]:
    """Hidden files left behind, but for the ones a finished piece of work keeps on purpose: the build
    record of a complete FMU (``.NAME.fmu.built``, fmus/builder.py) and a sweep folder's lock file."""
    return [p for p in Path(directory).rglob(".*") if not p.name.endswith(".fmu.built") and p.name != ".sweep.lock"]


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


# ----------------------------------------------------------------------------- 5, 6: config mistakes
_DESIGN = """{head}
[plant]
A = {A}
B = [[0], [1]]
C = [[1, 0]]
state_units = {units}
[observer]
t_settle = 0.15
"""


def _design(tmp_path, head='name = "inj"', A="[[0, 1], [-2, 3]]", units='["rad", "rad/s"]') -> Path:
    path = tmp_path / "design.toml"
    path.write_text(_DESIGN.format(head=head, A=A, units=units))
    return path


def _build_refused(tmp_path, config: Path) -> str:
    """``obsfmu build --config``: exit 2, one line, nothing written (no --out, no temporary build folder)."""
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    done = subprocess.run(OBSFMU + ["build", "--config", str(config), "--out", str(tmp_path / "out")],
                          capture_output=True, text=True, cwd=ROOT, env={**os.environ, "TMPDIR": str(scratch)},
                          timeout=120)
    assert done.returncode == 2, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and done.stderr.startswith("obsfmu: error: "), done.stderr
    assert not (tmp_path / "out").exists() and not list(scratch.iterdir())
    return done.stderr


@pytest.mark.parametrize("head, units, field", [
    ('name = "inj"\ndescription = "a \\u0001 b"', '["rad", "rad/s"]', "description: control character '\\x01'"),
    ('name = "inj"\ndescription = "two\\nlines"', '["rad", "rad/s"]', "description: control character '\\n'"),
    ('name = "inj"', '["rad", "rad\\u007f/s"]', "plant.state_units[2]: control character '\\x7f'"),
    ('name = "x\\n"', '["rad", "rad/s"]', "name: expected an identifier (letters, digits, _), got 'x\\n'"),
    ('name = "inj"', '["rad", "r\\u202Ead/s"]', "plant.state_units[2]: invisible format character U+202E at position 2"),
], ids=["control-character", "newline", "unit", "name-newline", "bidi-override"])
def test_a_bad_text_in_a_design_is_one_line_and_builds_nothing(tmp_path, head, units, field):
    assert field in _build_refused(tmp_path, _design(tmp_path, head=head, units=units))


def test_a_name_with_a_trailing_newline_is_not_an_identifier():
    from obsfmu.fmus.runtime.definition import valid_identifier
    assert valid_identifier("x") and not valid_identifier("x\n") and not valid_identifier("x\ny")


def test_a_plant_beyond_the_design_limit_is_refused_at_once(tmp_path):
    """201 states: refused from the size of plant.A; 2000 x 2000 (12 MB): from the size of the file."""
    from obsfmu.fmus.config import MAX_DIMENSION
    n = MAX_DIMENSION + 1
    over = tmp_path / "over"
    over.mkdir()
    matrix = "[" + ", ".join(["[" + ", ".join(["0"] * n) + "]"] * n) + "]"
    message = _build_refused(over, _design(over, A=matrix))
    assert f"plant.A: {n} states; a design has at most {MAX_DIMENSION} states, inputs and outputs" in message
    huge = _design(tmp_path, A="[" + ", ".join(["[" + "0, " * 1999 + "0]"] * 2000) + "]")
    assert "MiB; a design file has at most 4 MiB" in _build_refused(tmp_path, huge)


# ----------------------------------------------------------------------------- 2: SIGTERM and SIGHUP
def _wait_for(process: subprocess.Popen, condition, what: str, timeout: float = 180.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if process.poll() is not None or time.monotonic() > deadline:
            process.kill()
            pytest.fail(f"no {what}: {process.communicate()}")
        time.sleep(0.05)


def _stopped(process: subprocess.Popen, signum: int) -> tuple[str, str]:
    """Send ``signum``; the command ends by itself with 128 + signum and no traceback."""
    process.send_signal(signum)
    stdout, stderr = process.communicate(timeout=180)
    assert process.returncode == 128 + signum, stderr
    assert "Traceback" not in stdout + stderr and "Exception ignored" not in stderr, stderr
    return stdout, stderr


def _writing(directory: Path, name: str, size: int = 1):
    """True once the hidden temporary CSV of ``name`` holds ``size`` bytes (the run is stepping)."""
    return lambda: any(p.stat().st_size >= size for p in Path(directory).glob(f".{name}.csv.*.tmp"))


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_a_run_stopped_by_sigterm_or_sighup_keeps_its_rows(build_dir, tmp_path, signum):
    ensure_fmus(get("ship"), build_dir)
    csv = tmp_path / "T.csv"
    process = _start(["run", "ship", "--build-dir", build_dir, "--step", "1e-3", "--stop-time", "1e5", "--csv", csv])
    _wait_for(process, _writing(tmp_path, "T", 100_000), "rows")
    stdout, stderr = _stopped(process, signum)
    assert f"the rows so far are in {tmp_path / 'T.partial.csv'}" in stdout
    assert f"({signal.Signals(signum).name} again to kill at once)" in stderr
    assert not csv.exists() and not _hidden(tmp_path)
    rows = (tmp_path / "T.partial.csv").read_text().splitlines()
    assert len(rows) > 1000 and all(row.count(",") == 7 for row in rows)   # every row complete


@pytest.mark.parametrize("jobs", [1, 2])
def test_report_stopped_by_sigterm_keeps_the_rows_of_the_running_scenarios(build_dir, tmp_path, jobs):
    """``obsfmu report`` in an empty folder runs every scenario first (one by one, or in 2 workers)."""
    from obsfmu.fmus.scenarios import SCENARIOS
    for scenario in SCENARIOS.values():
        ensure_fmus(scenario, build_dir)
    out = tmp_path / "out"
    process = _start(["report", "--out", out, "--build-dir", build_dir, "--jobs", jobs])

    def running():   # ship finishes in about 1 s with its compiled kernels: wait for one that is still running
        names = [p.name.split(".")[1] for p in out.glob(".*.csv.*.tmp") if p.stat().st_size > 50_000]
        return [name for name in names if name != "ship"]
    _wait_for(process, running, "rows")
    stopped = running()
    stdout, _ = _stopped(process, signal.SIGTERM)
    interrupted = [name for name in SCENARIOS if f"{name}: interrupted at t = " in stdout]
    assert interrupted, stdout[-2000:]
    for name in interrupted:
        assert (out / f"{name}.partial.csv").exists()
        assert not (out / f"{name}.json").exists()                 # nothing passes for a finished run
    for name in set(stopped) - set(interrupted):                   # finished before the signal came: complete
        assert (out / f"{name}.json").exists()
    assert not _hidden(out) and not (out / "report.html").exists()


def test_all_stopped_by_sighup_while_it_builds_leaves_nothing_half_written(build_dir, tmp_path):
    """SIGHUP during ``obsfmu all``'s build of every FMU: unwinds like Ctrl-C, no partial FMU left."""
    out, fresh, scratch = tmp_path / "out", tmp_path / "build", tmp_path / "tmp"
    scratch.mkdir()
    process = _start(["all", "--out", out, "--build-dir", fresh, "--jobs", 1],
                     env={**os.environ, "TMPDIR": str(scratch)})
    _wait_for(process, lambda: list(fresh.rglob("*.fmu")), "first FMU")
    _, stderr = _stopped(process, signal.SIGHUP)
    assert "obsfmu: interrupted (SIGHUP)" in stderr
    assert not _hidden(fresh) and not _hidden(out) and not list(fresh.rglob("*.partial"))
    assert not list(scratch.glob("obsfmu_build_*"))                  # the temporary build folder is gone


def test_a_sweep_stopped_by_sigterm_keeps_its_finished_samples(build_dir, tmp_path):
    from obsfmu.fmus.campaign.store import load_rows
    ensure_fmus(get("ltv-ls-bounded"), build_dir)
    out = tmp_path / "sweep"
    # 100 samples of 10 s: about 10 s of work with the compiled kernels (10 samples of 1.5 s all finished before the
    # first batch was stored)
    process = _start(["sweep", "ltv-ls-bounded", "--vary", "plant.k[1]=-4:-2:100", "--stop-time", "10", "--workers",
                      1, "--out", out, "--build-dir", build_dir, "--no-plots"])
    _wait_for(process, lambda: list((out / "samples").glob("part-*.parquet")), "stored samples")
    _, stderr = _stopped(process, signal.SIGTERM)
    assert "interrupted: every finished sample is in" in stderr and "(SIGTERM)" in stderr
    rows = load_rows(out).to_pylist()
    assert 0 < len(rows) < 100 and all(row["status"] == "ok" for row in rows)
    assert not _hidden(out)


# ----------------------------------------------------------------------------- 3: a full disk
def _file_size_limit(limit: int):
    """For preexec_fn: files of this process at most ``limit`` bytes (a write beyond: EFBIG, as a full disk)."""
    def apply():
        import resource
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
    return apply


def test_a_csv_that_fills_the_disk_keeps_its_complete_rows_and_says_where(build_dir, tmp_path):
    ensure_fmus(get("ship"), build_dir)
    csv = tmp_path / "out.csv"
    done = subprocess.run(OBSFMU + ["run", "ship", "--build-dir", str(build_dir), "--step", "2e-4", "--stop-time", "100",
                                    "--csv", str(csv), "--output-interval", "2e-4"],   # every row: the CSV fills first
                          capture_output=True, text=True, cwd=ROOT, timeout=300,
                          preexec_fn=_file_size_limit(1_000_000))
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.strip().splitlines()
    partial = tmp_path / "out.partial.csv"
    assert line.startswith(f"obsfmu: error: --csv {csv}: File too large; the ")
    assert line.endswith(f" complete rows so far are in {partial}")
    rows = int(line.split("; the ")[1].split()[0])
    lines = partial.read_text().splitlines()
    assert len(lines) == rows + 1 and rows > 1000 and all(row.count(",") == 7 for row in lines)
    assert partial.stat().st_size <= 1_000_000 and not csv.exists() and not _hidden(tmp_path)


def test_a_run_whose_temporary_rows_fill_the_disk_first_says_so_and_keeps_the_csv_rows(build_dir, tmp_path):
    """At ship's output interval (1e-3 s) the CSV is 5 times smaller than the rows every run keeps in a
    temporary file: that file hit the limit first and numpy's short write ("8192 requested and 2176 written",
    no errno) came out as a bare error line. Now: the temporary folder named, the CSV's rows kept."""
    ensure_fmus(get("ship"), build_dir)
    csv = tmp_path / "out.csv"
    done = subprocess.run(OBSFMU + ["run", "ship", "--build-dir", str(build_dir), "--step", "2e-4", "--stop-time", "100",
                                    "--csv", str(csv)], capture_output=True, text=True, cwd=ROOT, timeout=300,
                          preexec_fn=_file_size_limit(1_000_000))
    assert done.returncode == 2, done.stderr
    kept, error = done.stderr.strip().splitlines()
    partial = tmp_path / "out.partial.csv"
    assert kept == f"obsfmu: the rows computed before the error are in {partial}"
    assert error.startswith("obsfmu: error: temporary directory ") and "set TMPDIR to a directory with room" in error
    lines = partial.read_text().splitlines()
    assert len(lines) > 100 and all(row.count(",") == 7 for row in lines) and not csv.exists()
    assert not _hidden(tmp_path)


def test_a_disk_full_from_the_start_writes_nothing_and_leaves_no_traceback(tmp_path, monkeypatch):
    import errno

    from obsfmu.fmus import output
    unraisable = []
    monkeypatch.setattr(sys, "unraisablehook", unraisable.append)

    def full(descriptor, data):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(output.os, "write", full)
    csv = tmp_path / "out.csv"
    with pytest.raises(output.OutputError, match=rf"^--out {csv}: No space left on device; nothing written$"):
        output.StreamingRecorder(csv, option="--out").begin(["a.x"])
    import gc
    gc.collect()
    assert not unraisable and not list(tmp_path.iterdir())


def test_a_file_replaced_on_a_full_disk_keeps_its_previous_version_and_is_named(tmp_path):
    import errno

    from obsfmu.fmus.output import OutputError, replacing
    target = tmp_path / "report.html"
    target.write_text("previous\n")
    with pytest.raises(OutputError, match=rf"^{target}: cannot be written \(No space left on device\)$"):
        with replacing(target) as temporary:
            temporary.write_text("half")
            raise OSError(errno.ENOSPC, "No space left on device")
    assert target.read_text() == "previous\n" and not _hidden(tmp_path)


# ----------------------------------------------------------------------------- 4: a tainted results folder
TAINT = "<script>alert(1)</script>\"'><img src=x onerror=alert(2)>"


def _tainted(value):
    """Every text of a record prefixed by ``TAINT`` (the scenario's name kept: it names the file)."""
    if isinstance(value, dict):
        return {key: item if key == "scenario" else _tainted(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_tainted(item) for item in value]
    return TAINT + value if isinstance(value, str) else value


@pytest.fixture(scope="module")
def ship_results(build_dir, tmp_path_factory):
    """A short ``ship`` run saved as ``obsfmu all`` saves it (figure, summary, record)."""
    from obsfmu.fmus import report
    from obsfmu.fmus.scenarios import run
    out = tmp_path_factory.mktemp("results") / "results"
    out.mkdir()
    result, summary = run("ship", build_dir, stop_time=0.05, step=1e-4)
    report.save_run(out, get("ship"), result, summary, 1.0, build_dir)
    return out


def test_a_tainted_record_is_written_escaped_and_embeds_no_file_from_outside(ship_results, tmp_path):
    import json
    import shutil

    from obsfmu.fmus import report
    out = tmp_path / "results"
    shutil.copytree(ship_results, out)
    secret = tmp_path / "secret.svg"
    secret.write_text("<svg>SECRET-OUTSIDE</svg>")
    (out / "link.svg").symlink_to(secret)
    record = json.loads((out / "ship.json").read_text())
    tainted = _tainted(record)
    tainted["summary"]["metrics"] = {TAINT + key: value for key, value in record["summary"]["metrics"].items()}
    tainted["changed"] = {TAINT: 1.5}
    tainted["figures"] = ["../secret.svg", str(secret), "link.svg", *record["figures"]]
    (out / "ship.json").write_text(json.dumps(tainted))
    assert report.load_run(out, "ship") is not None                    # a record of the right shape
    page = report.write_report(out, names=["ship"]).read_text()
    assert "<script" not in page and "<img src=x" not in page and "onerror=alert(2)>" not in page
    assert page.count("&lt;script&gt;alert(1)&lt;/script&gt;") > 10    # shown, as text
    assert "SECRET-OUTSIDE" not in page and _b64("SECRET-OUTSIDE") not in page
    assert 'data-file="ship.svg"' in page                             # the figure of the folder itself


def _b64(text: str) -> str:
    import base64
    return base64.b64encode(f"<svg>{text}</svg>".encode()).decode()


@pytest.mark.parametrize("field, value", [("fmus", [{"variables": TAINT}]), ("step", TAINT), ("figures", TAINT),
                                          ("summary", {"lines": [], "metrics": {"x": TAINT}, "reference": ""})],
                         ids=["fmus", "step", "figures", "summary"])
def test_a_record_of_another_shape_is_not_used(ship_results, tmp_path, field, value):
    import json
    import shutil

    from obsfmu.fmus import report
    out = tmp_path / "results"
    shutil.copytree(ship_results, out)
    record = json.loads((out / "ship.json").read_text())
    record[field] = value
    (out / "ship.json").write_text(json.dumps(record))
    assert report.load_run(out, "ship") is None and not report.has_run(out, "ship")
    page = report.write_report(out, names=["ship"]).read_text()
    assert "Missing scenarios (no results): ship" in page and "<script" not in page


# ----------------------------------------------------------------------------- 9: the report's claims
def test_every_claim_is_marked_met_or_not_met_with_its_numbers(ship_results, tmp_path):
    import json
    import shutil
    from html import unescape

    from obsfmu.fmus import report
    from obsfmu.fmus.claims import CHECKS, reference_interval, verdict
    assert verdict(CHECKS["uio-ftdrem"][1], {"t_omega_1e-4": 4.168}, "s") == \
        ("not met", "measured 4.168 s, claimed: at most 3.4 s")                     # the audit's case
    assert verdict(CHECKS["uio-ftdrem"][1], {"t_omega_1e-4": float("inf")}, "s")[0] == "not met"
    assert verdict(CHECKS["uio-ftdrem"][1], {}, "s")[0] == "not measured"
    assert reference_interval("uio-ftdrem", 20.0, "s") == "over the last 20 % of the run, t = 16 .. 20 s"
    out = tmp_path / "results"
    shutil.copytree(ship_results, out)
    record = json.loads((out / "ship.json").read_text())
    record["summary"]["metrics"]["settling_time_y"] = 0.45
    (out / "ship.json").write_text(json.dumps(record))
    page = unescape(report.write_report(out, names=["ship"]).read_text())
    assert '<td class="not-met" data-check="settling_time_y">not met</td><td>measured 0.45 s, claimed: at most 0.3 s' \
        in page
    assert ('>not measured</td><td>max_deviation_from_paper_table is not measured in this run; claimed: at most '
            '5e-05</td>') in page                                                   # 0.05 s: before the table ends
    assert "It holds over the whole run, t = 0 .. 0.05 s." in page
    assert "The figure shows the whole run, t = 0 .. 0.05 s." in page
    assert "not stated" not in page and 'settling_time_y</td><td class="number"' in page
