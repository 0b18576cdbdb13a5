"""Result files that survive: checked before a run, streamed during it, complete or marked partial.

* :func:`check_file` / :func:`check_directory` -- an output path is usable (its directory exists
  and is writable, it is not a directory where a file is expected, ...) *before* the simulation
  starts; the error names the option.
* :class:`StreamingRecorder` -- a :class:`fmus.master.Recorder` that keeps nothing but a small
  block in memory: every communication point goes to an anonymous scratch file (the
  :class:`~fmus.result.Result` the summary needs is a read-only memory map of it) and, optionally,
  to a CSV.  The CSV is written under a hidden temporary name in the target directory and renamed
  into place only when the run is complete; an interrupted (or failed) run renames it to
  ``NAME.partial.csv`` instead.  A killed process leaves only the hidden ``.NAME.PID.*.tmp``: never a
  truncated file under the name of a complete one; the next run writing ``NAME`` removes it (its
  process is gone).
* :func:`replacing` -- the same rename-into-place for every other output (figures, summaries, the
  report).

A full disk (or a file-size limit) while writing is an :class:`OutputError` naming the option and
the path, and no temporary file stays behind: a CSV keeps its complete rows so far in
``NAME.partial.csv`` (the last, cut row dropped), any other file its previous version.
"""

from __future__ import annotations

import contextlib
import errno
import os
import tempfile
import time
from glob import escape as glob_escape
from pathlib import Path

import numpy as np

from .master import Recorder
from .result import Result

__all__ = ["OutputError", "check_file", "check_directory", "partial_path", "replacing", "StreamingRecorder", "file_mode"]


class OutputError(ValueError):
    """An output path cannot be written; the message names the option."""


def _probe(option: str, path: Path, directory: Path) -> None:
    try:
        with tempfile.TemporaryFile(dir=directory):
            pass
    except OSError as exc:
        raise OutputError(f"{option} {path}: cannot write in {directory} ({exc.strerror or exc})") from None


def check_file(option: str, path: Path | str, suffixes: tuple[str, ...] = ()) -> Path:
    """``path`` can be written as a file: not a directory, in an existing writable directory."""
    path = Path(path)
    if path.is_dir():
        raise OutputError(f"{option} {path}: is a directory, expected a file name")
    if suffixes and path.suffix.lower() not in suffixes:
        raise OutputError(f"{option} {path}: expected a file name ending in {' or '.join(suffixes)}")
    directory = path.parent
    if not directory.exists():
        raise OutputError(f"{option} {path}: directory {directory} does not exist")
    if not directory.is_dir():
        raise OutputError(f"{option} {path}: {directory} is not a directory")
    _probe(option, path, directory)
    return path


def check_directory(option: str, path: Path | str, writable: bool = True) -> Path:
    """``path`` is (or is created as) a directory; with ``writable``, files can be created in it."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OutputError(f"{option} {path}: is a file, expected a directory")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{option} {path}: cannot create the directory ({exc.strerror or exc})") from None
    if writable:
        _probe(option, path, path)
    return path


def partial_path(path: Path) -> Path:
    """``out.csv`` -> ``out.partial.csv``: where the rows of an unfinished run go."""
    return path.with_name(f"{path.stem}.partial{path.suffix}")


def file_mode() -> int:
    """Permissions of a new file under the current umask (temporary files are created 0600)."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def _hidden_temporary(target: Path) -> tuple[int, Path]:
    """A temporary file beside ``target`` (same file system: renaming it is atomic), hidden, ``.tmp``, named
    with this process's id: its descriptor (unbuffered: a failed write leaves nothing pending) and its path.
    Those of earlier writers that were killed are removed first (:func:`remove_stale_temporaries`)."""
    remove_stale_temporaries(target)
    descriptor, name = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.{os.getpid()}.", suffix=".tmp")
    os.fchmod(descriptor, file_mode())
    return descriptor, Path(name)


#: a temporary file without a writer's id (an older obsfmu) is stale after this many seconds
STALE_AFTER = 3600.0


def remove_stale_temporaries(target: Path) -> list[Path]:
    """Remove the hidden temporary files of ``target`` whose writer is gone (``.NAME.PID.*.tmp`` of a process
    that no longer exists, or one without a process id older than :data:`STALE_AFTER`): a run killed with
    SIGKILL leaves its temporary file, which nothing else would ever remove.  Returns what was removed."""
    removed = []
    for path in target.parent.glob(f".{glob_escape(target.name)}.*.tmp"):
        middle = path.name[len(target.name) + 2:-len(".tmp")]
        pid = middle.split(".", 1)[0]
        try:
            if pid.isdigit() and "." in middle:
                if _alive(int(pid)):
                    continue
            elif time.time() - path.stat().st_mtime < STALE_AFTER:
                continue
            path.unlink()
            removed.append(path)
        except OSError:
            continue                           # gone meanwhile, or not ours to remove
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True                            # another user's process
    return True


def _no_room(exc: OSError) -> bool:
    """A write refused for want of room: a full disk or quota, a file-size limit, an I/O error."""
    return exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO)


@contextlib.contextmanager
def replacing(target: Path | str):
    """Yield a temporary path beside ``target``; rename it to ``target`` if the block succeeds (a full
    disk: :class:`OutputError` naming ``target``, which keeps its previous version)."""
    target = Path(target)
    descriptor, temporary = _hidden_temporary(target)
    os.close(descriptor)
    try:
        yield temporary
        os.replace(temporary, target)
    except OSError as exc:
        if not _no_room(exc):
            raise
        raise OutputError(f"{target}: cannot be written ({exc.strerror or exc})") from None
    finally:
        temporary.unlink(missing_ok=True)


class _CsvStream:
    """Rows to a hidden temporary CSV; optionally only those nearest to ``t0 + k * interval``.

    The selection is :meth:`Result.sampled`'s, made on the fly: a target time is served by the
    row before it or the row after it, whichever is nearer (the earlier on a tie), and the last
    row is always written.  A write refused for want of room ends the stream (:meth:`_out_of_room`).
    """

    def __init__(self, target: Path, columns: list[str], interval: float | None, option: str = "--csv"):
        self.target, self.interval, self.option = target, interval, option
        self.descriptor, self.temporary = _hidden_temporary(target)
        self.size = 0              # bytes written, every one of them part of a complete line
        self.rows_written = -1     # rows on disk (the header is not one)
        self.lines: list[str] = [",".join(["time"] + columns) + "\n"]
        self.flush()
        self.format = ",".join(["%.17g"] * (len(columns) + 1)) + "\n"
        self.previous: tuple[int, float, np.ndarray] | None = None
        self.written = -1          # index of the last row written
        self.row = -1
        self.next_target = 0       # k of the next target time t0 + k * interval
        self.t0 = 0.0

    def add(self, t: float, values: np.ndarray) -> None:
        self.row += 1
        if self.interval is None:
            self._write(self.row, t, values)
            return
        if self.row == 0:
            self.t0 = t
        while (target := self.t0 + self.next_target * self.interval) <= t:
            if self.previous is not None and target - self.previous[1] <= t - target:
                self._write(*self.previous)
            else:
                self._write(self.row, t, values)
            self.next_target += 1
        self.previous = (self.row, t, np.array(values, dtype=float))

    def _write(self, row: int, t: float, values) -> None:
        if row > self.written:
            self.lines.append(self.format % (t, *values))
            self.written = row

    def flush(self) -> None:
        if self.descriptor is None:   # ended (for want of room)
            return
        data = memoryview("".join(self.lines).encode())
        done = 0
        try:
            while done < len(data):
                done += os.write(self.descriptor, data[done:])
        except OSError as exc:
            if not _no_room(exc):
                raise
            self._out_of_room(exc, bytes(data[:done]))
        self.size += len(data)
        self.rows_written += len(self.lines)
        self.lines.clear()

    def _out_of_room(self, exc: OSError, written: bytes) -> None:
        """Keep the complete rows on disk in the partial file (or nothing), then raise naming the path."""
        complete = written[:written.rfind(b"\n") + 1]
        rows = self.rows_written + complete.count(b"\n")
        kept = None
        try:
            if rows > 0:
                os.ftruncate(self.descriptor, self.size + len(complete))   # drop the cut row
                kept = self._rename(complete=False)
        except OSError:
            kept = None
        finally:
            self.discard()
        where = f"the {rows} complete rows so far are in {kept}" if kept else "nothing written"
        raise OutputError(f"{self.option} {self.target}: {exc.strerror or exc}; {where}") from None

    def _rename(self, complete: bool) -> Path:
        os.fsync(self.descriptor)
        os.close(self.descriptor)
        self.descriptor = None
        final, stale = (self.target, partial_path(self.target)) if complete else \
            (partial_path(self.target), self.target)
        os.replace(self.temporary, final)
        stale.unlink(missing_ok=True)  # an earlier run's file would pass for this run's
        return final

    def close(self, complete: bool) -> Path | None:
        """Finish the file and rename it: to the target if ``complete``, else to its partial name
        (None: the stream ended already, for want of room)."""
        if self.descriptor is None:
            return None
        if self.previous is not None:
            self._write(*self.previous)  # the last row, always
        self.flush()
        try:
            return self._rename(complete)
        except OSError as exc:
            self.discard()
            if not _no_room(exc):
                raise
            raise OutputError(f"{self.option} {self.target}: {exc.strerror or exc}; nothing written") from None

    def discard(self) -> None:
        if self.descriptor is not None:
            os.close(self.descriptor)
            self.descriptor = None
        self.temporary.unlink(missing_ok=True)


class StreamingRecorder(Recorder):
    """Every communication point to disk as it comes (bounded memory), optionally also to a CSV.

    Parameters
    ----------
    csv : Path, optional
        Target CSV (``time`` and one column per output); written under a hidden temporary name
        and renamed by :meth:`close`.
    interval : float, optional
        Write only the rows nearest to multiples of ``interval`` to the CSV (the :class:`Result`
        keeps every row).
    block_rows : int
        Rows kept in memory between two writes.
    option : str
        The option that named ``csv``, for the messages.
    """

    def __init__(self, csv: Path | None = None, interval: float | None = None, block_rows: int = 1024,
                 option: str = "--csv"):
        self.csv, self.interval, self.block_rows, self.option = csv, interval, block_rows, option
        self._csv: _CsvStream | None = None
        self._scratch = None
        self._rows = self._filled = 0

    def begin(self, columns: list[str]) -> None:
        self.discard()
        super().begin(columns)
        self._scratch = tempfile.TemporaryFile(prefix="obsfmu_rows_")
        self._block = np.empty((self.block_rows, len(self.columns) + 1))
        self._filled = 0
        self._rows = 0
        self._csv = _CsvStream(self.csv, self.columns, self.interval, self.option) if self.csv else None

    def record(self, t: float, values: np.ndarray) -> None:
        row = self._block[self._filled]
        row[0] = t
        row[1:] = values
        self._filled += 1
        if self._csv:
            self._csv.add(t, row[1:])
        if self._filled == self.block_rows:
            self._flush()

    def _flush(self) -> None:
        if self._scratch is None:     # ended (for want of room): the CSV's rows are still finished by close
            return
        try:
            self._block[:self._filled].tofile(self._scratch)
        except OSError as exc:        # numpy reports a short write ("8192 requested and 2176 written") without errno
            if exc.errno is not None and not _no_room(exc):
                raise
            self._scratch.close()
            self._scratch = None
            reason = exc.strerror or "a short write: no room for the file"
            raise OutputError(f"temporary directory {tempfile.gettempdir()}: {reason} (a run keeps its rows there; "
                              "set TMPDIR to a directory with room)") from None
        self._rows += self._filled
        self._filled = 0
        if self._csv:
            self._csv.flush()

    @property
    def rows(self) -> int:
        """Communication points recorded so far."""
        return self._rows + self._filled

    def result(self) -> Result:
        """The rows so far as a :class:`Result` whose arrays are a read-only map of the scratch file."""
        self._flush()
        self._scratch.flush()
        width = len(self.columns) + 1
        if self._rows:
            data = np.asarray(np.memmap(self._scratch, dtype=float, mode="r", shape=(self._rows, width)))
        else:
            data = np.zeros((0, width))
        return Result(data[:, 0], list(self.columns), data[:, 1:])

    def close(self, complete: bool) -> Path | None:
        """Finish the CSV: renamed to its target if ``complete``, else to ``NAME.partial.csv``.

        Returns the file written (None without a CSV or when nothing was recorded).
        """
        stream, self._csv = self._csv, None
        if stream is None:
            return None
        if stream.row < 0:
            stream.discard()
            return None
        self._flush()
        return stream.close(complete)

    def discard(self) -> None:
        """Drop the temporary CSV (if any) without renaming it."""
        if self._csv is not None:
            self._csv.discard()
            self._csv = None
