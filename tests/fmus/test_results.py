"""Results that survive (issue 13, item 5): streamed, renamed into place, partial when interrupted.

The recorder is tested on synthetic rows; Ctrl-C (SIGINT) and a kill on a running ``obsfmu run``
in a subprocess (the only way to send a real signal to a running command).
"""

from __future__ import annotations

import mmap
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from obsfmu.fmus.output import StreamingRecorder, partial_path, replacing
from obsfmu.fmus.result import Result
from obsfmu.fmus.scenarios import ensure_fmus, get

COLUMNS = ["a.x[1]", "a.x[2]", "b.y"]


def _rows(count: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    times = np.cumsum(np.r_[0.0, rng.uniform(0.001, 0.02, count - 1)])  # uneven steps
    return times, rng.normal(size=(count, len(COLUMNS)))


def _record(recorder: StreamingRecorder, times, values) -> None:
    recorder.begin(COLUMNS)
    for t, row in zip(times, values):
        recorder.record(t, row)


def _hidden(directory: Path) -> list[Path]:
    return [p for p in directory.iterdir() if p.name.startswith(".")]


@pytest.mark.parametrize("interval", [None, 0.05, 0.013])
def test_streamed_csv_equals_the_in_memory_result(tmp_path, interval):
    times, values = _rows(3000)
    csv = tmp_path / "out.csv"
    recorder = StreamingRecorder(csv, interval, block_rows=128)
    _record(recorder, times, values)
    result = recorder.result()
    assert recorder.close(complete=True) == csv
    np.testing.assert_array_equal(result.time, times)
    np.testing.assert_array_equal(result.values, values)
    expected = Result(times, COLUMNS, values)
    expected = expected.sampled(interval) if interval else expected
    written = Result.from_csv(csv)
    assert written.columns == COLUMNS
    np.testing.assert_array_equal(written.time, expected.time)       # %.17g: bit-exact round trip
    np.testing.assert_array_equal(written.values, expected.values)
    assert not _hidden(tmp_path) and not partial_path(csv).exists()


def test_the_result_is_a_map_of_a_file_not_rows_in_memory(tmp_path):
    times, values = _rows(5000)
    recorder = StreamingRecorder(block_rows=256)
    _record(recorder, times, values)
    assert recorder._block.shape[0] == 256                    # what the recorder holds in memory
    result = recorder.result()
    base = result.values
    while getattr(base, "base", None) is not None and not isinstance(base, mmap.mmap):
        base = base.base
    assert isinstance(base, mmap.mmap)
    np.testing.assert_array_equal(result.values, values)


def test_an_unfinished_run_leaves_a_file_named_partial_and_no_stale_result(tmp_path):
    csv = tmp_path / "out.csv"
    csv.write_text("time,a\n0,1\n")                           # an earlier run's complete file
    times, values = _rows(500)
    recorder = StreamingRecorder(csv, block_rows=64)
    _record(recorder, times[:321], values[:321])
    assert recorder.close(complete=False) == tmp_path / "out.partial.csv"
    assert not csv.exists() and not _hidden(tmp_path)
    kept = Result.from_csv(tmp_path / "out.partial.csv")
    np.testing.assert_array_equal(kept.time, times[:321])
    # the next complete run replaces the partial file
    recorder = StreamingRecorder(csv)
    _record(recorder, times, values)
    recorder.close(complete=True)
    assert csv.exists() and not (tmp_path / "out.partial.csv").exists()


def test_an_interruption_during_the_final_write_leaves_no_file_that_looks_complete(tmp_path, monkeypatch):
    csv = tmp_path / "out.csv"
    times, values = _rows(2000)
    recorder = StreamingRecorder(csv, block_rows=100)
    _record(recorder, times, values)

    def interrupted(fd):
        raise KeyboardInterrupt
    monkeypatch.setattr(os, "fsync", interrupted)
    with pytest.raises(KeyboardInterrupt):
        recorder.close(complete=True)
    assert not csv.exists() and not partial_path(csv).exists()
    assert all(p.name.endswith(".tmp") for p in _hidden(tmp_path))


def test_replacing_keeps_the_old_file_when_the_write_fails(tmp_path):
    target = tmp_path / "summary.txt"
    target.write_text("old\n")
    with pytest.raises(RuntimeError):
        with replacing(target) as temporary:
            temporary.write_text("half")
            raise RuntimeError("disk full")
    assert target.read_text() == "old\n" and not _hidden(tmp_path)
    with replacing(target) as temporary:
        temporary.write_text("new\n")
    assert target.read_text() == "new\n" and oct(target.stat().st_mode & 0o777) != "0o600"


# ----------------------------------------------------------------------------- signals on a running `obsfmu run`
@pytest.fixture(scope="module")
def long_run(build_dir):
    """``obsfmu run ship`` for 1e5 s at 1e-3 s: runs until it is stopped."""
    ensure_fmus(get("ship"), build_dir)

    def start(csv: Path) -> subprocess.Popen:
        return subprocess.Popen([sys.executable, "-m", "obsfmu", "run", "ship", "--build-dir", str(build_dir),
                                 "--step", "1e-3", "--stop-time", "1e5", "--csv", str(csv)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    return start


def _wait_for_rows(process: subprocess.Popen, directory: Path, size: int = 100_000, timeout: float = 120.0) -> None:
    """Until the hidden temporary CSV holds ``size`` bytes (the run is stepping)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert process.poll() is None, process.communicate()
        if any(p.stat().st_size >= size for p in _hidden(directory)):
            return
        time.sleep(0.1)
    process.kill()
    pytest.fail("the run wrote no rows in time")


def test_ctrl_c_stops_the_run_cleanly_and_keeps_the_rows(long_run, tmp_path):
    csv = tmp_path / "out.csv"
    csv.write_text("time,stale\n0,0\n")                      # an earlier run's result
    process = long_run(csv)
    _wait_for_rows(process, tmp_path)
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=120)
    assert process.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    line = next(line for line in out.splitlines() if "interrupted at t = " in line)
    assert line.endswith(f"s; the rows so far are in {partial_path(csv)}")
    stopped_at = float(line.split("interrupted at t = ")[1].split()[0])
    assert not csv.exists() and not _hidden(tmp_path)
    kept = Result.from_csv(partial_path(csv))                # every row complete (loadtxt refuses ragged rows)
    assert kept.columns == ["plant.y", "plant.x[1]", "plant.x[2]", "observer.x_hat[1]", "observer.x_hat[2]",
                            "observer.y_hat", "controller.u"]
    assert len(kept.time) > 100 and np.all(np.diff(kept.time) > 0)
    np.testing.assert_allclose(kept.time, 1e-3 * np.arange(len(kept.time)), atol=1e-9)
    assert kept.time[-1] == pytest.approx(stopped_at, rel=1e-5)
    assert np.all(np.isfinite(kept.values))


def test_a_killed_run_leaves_no_file_that_looks_complete(long_run, tmp_path):
    csv = tmp_path / "out.csv"
    process = long_run(csv)
    _wait_for_rows(process, tmp_path, size=20_000)
    process.kill()
    process.communicate(timeout=60)
    assert not csv.exists() and not partial_path(csv).exists()
    assert [p.name.endswith(".tmp") for p in _hidden(tmp_path)] == [True]
    # issue 37.8: the next writer of out.csv removes what the killed one left (its process is gone)
    with replacing(csv) as temporary:
        temporary.write_text("t\n")
    assert csv.read_text() == "t\n" and _hidden(tmp_path) == []


def test_a_run_read_between_its_points_through_a_cubic_spline_is_fourth_order():
    """``Result.at`` (summaries compare an adaptive run with a reference at the reference's points): on
    unequal points, halving the spacing cuts the error of sin by about 16, not 4 as a linear reading."""
    errors = []
    for count in (40, 80):
        spacing = 4.0 / count                                     # unequal points, spacing about halved
        time = np.linspace(0.0, 4.0, count + 1) + 0.3 * spacing * np.sin(np.arange(count + 1.0)) * (
            np.arange(count + 1) % count != 0)
        result = Result(time, ["a.x[1]", "a.x[2]"], np.column_stack([np.sin(time), np.cos(time)]))
        grid = np.linspace(0.5, 3.5, 61)
        errors.append(np.abs(result.at(grid, "a.x") - np.column_stack([np.sin(grid), np.cos(grid)])).max())
    assert errors[1] < 1e-7 and errors[0] / errors[1] > 8, errors      # 8.3e-7, 2.3e-8 (linear: 2.0e-3, 3.2e-4)
    with pytest.raises(ValueError, match="times: .* leave the run"):
        result.at([4.5], "a.x")


def test_temporary_files_of_killed_runs_are_removed_by_the_next_run(tmp_path):
    """Issue 37: SIGKILL of `run --csv out.csv` left `.out.csv.*.tmp` (174 KB) that no later run removed."""
    from obsfmu.fmus.output import STALE_AFTER, replacing
    target = tmp_path / "out.csv"
    gone = subprocess.Popen(["true"])
    gone.wait()                                                        # a process id that no longer runs
    killed = tmp_path / f".out.csv.{gone.pid}.k2j3.tmp"
    running = tmp_path / f".out.csv.{os.getpid()}.a8f0.tmp"            # a writer still at work: kept
    old = tmp_path / ".out.csv.x7q1zz.tmp"                             # an older obsfmu's name, an hour old
    recent = tmp_path / ".out.csv.r4nd0m.tmp"
    for path in (killed, running, old, recent):
        path.write_text("1,2\n")
    os.utime(old, (time.time() - STALE_AFTER - 5,) * 2)
    with replacing(target) as temporary:
        temporary.write_text("time\n")
    assert target.read_text() == "time\n"
    assert not killed.exists() and not old.exists() and running.exists() and recent.exists()


def test_a_full_disk_while_building_names_the_fmu(tmp_path, monkeypatch, capsys):
    """Issue 37: `--build-dir` on a full disk said `No space left on device`, naming no path."""
    import errno
    import zipfile

    from obsfmu.fmus.cli import main as cli

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(zipfile.ZipFile, "writestr", full)
    assert cli.main(["build", "--out", str(tmp_path / "build")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"obsfmu: error: {tmp_path / 'build'}/") and err.endswith(".fmu: No space left on device")
    assert len(err.splitlines()) == 1 and not list((tmp_path / "build").glob("*.fmu*"))
