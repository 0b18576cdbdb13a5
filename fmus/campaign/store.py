"""The campaign's rows on disk: a Parquet dataset written incrementally, never corrupt.

``OUT/samples/`` is a Parquet dataset (read it with ``pyarrow.dataset``,
``pandas.read_parquet`` or :func:`load_rows`).  Every batch of finished
samples becomes one new file ``part-<time ns>-<pid>.parquet``, written to a
hidden temporary name (Parquet readers skip names starting with ``.``),
flushed to disk and renamed into place: a killed campaign leaves only
complete files, and every sample that finished before the kill is in one.
At the end of a campaign the parts are compacted into one file (written
first, the old parts removed after).  A sample may therefore appear in
more than one file for a moment, or after a rerun; :func:`load_rows` keeps
the newest row of each ``sample_id`` (files in name order = time order).
"""

from __future__ import annotations

import os
import time as wallclock
from contextlib import contextmanager
from pathlib import Path

import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from .errors import CampaignError

__all__ = ["Store", "load_rows", "rows_to_table", "STRING_COLUMNS"]

STRING_COLUMNS = ("sample_id", "status", "reason", "worker", "fmu_set", "warnings", "invocation", "finished_at")
BOOL_COLUMNS = ("converged",)
INT_COLUMNS = ("run_in_session",)


def _type(name: str) -> pa.DataType:
    if name in STRING_COLUMNS:
        return pa.string()
    if name in BOOL_COLUMNS:
        return pa.bool_()
    if name in INT_COLUMNS:
        return pa.int64()
    return pa.float64()


def rows_to_table(rows: list[dict]) -> pa.Table:
    """Rows (dicts) -> a table: the union of their keys in first-seen order, missing values null."""
    names = list(dict.fromkeys(name for row in rows for name in row))
    return pa.table({name: pa.array([row.get(name) for row in rows], type=_type(name)) for name in names})


def _fsync_directory(directory: Path) -> None:
    try:
        handle = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(handle)
    except OSError:
        pass
    finally:
        os.close(handle)


def _atomic(path: Path, write) -> None:
    """``write(temporary path)``, fsync, rename to ``path``."""
    partial = path.with_name(f".{path.name}.{os.getpid()}.partial")
    try:
        write(partial)
        with open(partial, "rb") as handle:
            os.fsync(handle.fileno())
        os.replace(partial, path)
    finally:
        partial.unlink(missing_ok=True)
    _fsync_directory(path.parent)


class Store:
    """The dataset directory ``OUT/samples`` and the CSV ``OUT/samples.csv``."""

    def __init__(self, out: Path | str):
        self.out = Path(out)
        self.directory = self.out / "samples"

    @contextmanager
    def locked(self):
        """Hold ``OUT/.sweep.lock`` exclusively (flock): a second sweep into the same folder is refused at once
        (two at a time raced on the part files and one ended with a bare path as its error)."""
        self.out.mkdir(parents=True, exist_ok=True)
        with open(self.out / ".sweep.lock", "a") as lock:
            try:
                import fcntl
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except ImportError:                   # not POSIX: no lock (one sweep per folder is then the user's care)
                pass
            except OSError:
                raise CampaignError(f"--out {self.out}: another sweep is writing into it; wait until it ends or "
                                    f"give another --out") from None
            yield self

    def parts(self) -> list[Path]:
        return sorted(self.directory.glob("part-*.parquet")) if self.directory.is_dir() else []

    def append(self, rows: list[dict]) -> Path | None:
        """Write ``rows`` as one new part file (atomically); returns its path."""
        if not rows:
            return None
        self.directory.mkdir(parents=True, exist_ok=True)
        path = self.directory / f"part-{wallclock.time_ns():020d}-{os.getpid()}.parquet"
        table = rows_to_table(rows)
        _atomic(path, lambda p: pq.write_table(table, p))
        return path

    def read(self) -> pa.Table | None:
        """Every stored row, the newest of each sample id; None when nothing is stored."""
        return load_rows(self.directory)

    def compact(self) -> None:
        """Replace the part files by one (the deduplicated union)."""
        parts = self.parts()
        if len(parts) < 2:
            return
        table = self.read()
        path = self.directory / f"part-{wallclock.time_ns():020d}-{os.getpid()}.parquet"
        _atomic(path, lambda p: pq.write_table(table, p))
        for part in parts:
            part.unlink(missing_ok=True)
        _fsync_directory(self.directory)

    def write_text(self, name: str, text: str) -> Path:
        self.out.mkdir(parents=True, exist_ok=True)
        path = self.out / name
        _atomic(path, lambda p: p.write_text(text))
        return path

    def write_csv(self, table: pa.Table, path: Path | None = None) -> Path:
        path = Path(path or self.out / "samples.csv")
        _atomic(path, lambda p: pacsv.write_csv(table, p))
        return path


def load_rows(directory: Path | str) -> pa.Table | None:
    """Read a campaign's ``samples`` dataset (or the campaign directory): the newest row of each sample id."""
    directory = Path(directory)
    if (directory / "samples").is_dir():
        directory = directory / "samples"
    parts = sorted(directory.glob("part-*.parquet")) if directory.is_dir() else []
    if not parts:
        return None
    table = pa.concat_tables([pq.read_table(part) for part in parts], promote_options="default")
    newest = {sample: index for index, sample in enumerate(table["sample_id"].to_pylist())}
    return table.take(sorted(newest.values()))
