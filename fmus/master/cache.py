"""The extracted FMUs, once per content: a run opens an FMU from here instead of unzipping it again.

An FMU is unzipped only within stated limits, checked on the archive's directory before anything is
written and again while writing (a header that lies about a size cannot exceed them either):

* :data:`MAX_UNPACKED` -- 1 GiB in all (a standalone FMU, ``obsfmu build --standalone``: ~60 MB);
* :data:`MAX_ENTRIES` -- 10 000 entries (a standalone FMU: ~300);
* :data:`MAX_RATIO` -- an entry over :data:`RATIO_FROM` (1 MiB) unpacks to at most 100 times its compressed
  size (an FMU's code and binaries compress 2-4 times; a zip bomb's zeros about 1000 times).

Beyond them, and for names that leave the folder (``..``, absolute, drive letters, backslashes), the FMU is
refused at once (:class:`~fmus.master.errors.SimulationError` naming the limit) and nothing stays in the cache.

An open FMU keeps reading its folder: ``fmi2Reset`` creates the slave again from ``resources/`` (its
definition), so a :class:`~fmus.master.Session` reused for minutes (the workers of ``obsfmu sweep``) needs
its entries long after it opened them, while other runs on the machine (a test suite extracts hundreds of
FMUs) prune the cache.  :func:`leased` hands out the folder with a :class:`Lease` -- a shared ``flock`` on
the entry's :data:`LEASE` file, held until the instance closes (or its process ends) -- and pruning, in any
process, skips an entry it cannot lock exclusively.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
import time as wallclock
import uuid
import zipfile
from pathlib import Path, PurePosixPath

from ..caches import obsfmu_cache, writable
from .errors import SimulationError

try:
    import fcntl
except ImportError:                      # Windows: no leases, pruning removes what it chooses (as before)
    fcntl = None

__all__ = ["EXTRACT_CACHE", "EXTRACT_CACHE_SIZE", "ABANDONED_AFTER", "MAX_UNPACKED", "MAX_ENTRIES", "MAX_RATIO",
           "RATIO_FROM", "LEASE", "Lease", "extracted", "leased", "unzip"]

#: extracted FMUs, by content (``OBSFMU_CACHE`` overrides); the newest are kept
EXTRACT_CACHE = obsfmu_cache() / "extracted"
EXTRACT_CACHE_SIZE = 64
#: a partial extraction (``.<digest>.*``) this old was left by a killed run: removed when pruning
ABANDONED_AFTER = 3600.0
#: the limits of an FMU to unzip (module docstring)
MAX_UNPACKED = 1 << 30
MAX_ENTRIES = 10_000
MAX_RATIO = 100
RATIO_FROM = 1 << 20
_CHUNK = 1 << 20
#: the file of an entry that its users lock (shared) and pruning locks (exclusive)
LEASE = ".obsfmu-in-use"
_ATTEMPTS = 5


class Lease:
    """A cache entry in use: pruning leaves it alone until :meth:`release` (idempotent) or the process ends."""

    def __init__(self, fd: int | None):
        self._fd = fd

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)           # closing the file drops its lock
            self._fd = None

    __del__ = release                    # an instance dropped without close: its entry may go again


def _lease(folder: Path) -> Lease | None:
    """A shared lock on ``folder``'s :data:`LEASE`; None when ``folder`` is gone or being pruned."""
    if fcntl is None:
        return Lease(None) if folder.is_dir() else None
    try:
        fd = os.open(folder / LEASE, os.O_RDWR | os.O_CREAT, 0o600)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        if os.stat(folder / LEASE).st_ino == os.fstat(fd).st_ino:   # still there, not renamed away meanwhile
            return Lease(fd)
    except OSError:
        pass
    os.close(fd)
    return None


def extracted(fmu: Path) -> Path:
    """The folder of :func:`leased`, not held: for a caller that reads it at once (pruning may remove it later)."""
    folder, lease = leased(fmu)
    lease.release()
    return folder


def leased(fmu: Path) -> tuple[Path, Lease]:
    """The FMU unzipped once per content (sha256) into :data:`EXTRACT_CACHE` and reused, with a
    :class:`Lease` that keeps pruning from removing it until released (module docstring).

    Unzipping every FMU afresh (its bundled code: ~100 files) cost 0.15 s of every ``obsfmu run``, plus
    compiling the bundled modules again each time.  Entries are written to a temporary sibling and renamed
    (concurrent runs never see a partial one); beyond :data:`EXTRACT_CACHE_SIZE` the least recently used go.
    A cache that cannot be written (a read-only file system) is replaced by a private temporary one
    (:func:`fmus.caches.writable`).
    """
    digest = hashlib.sha256(Path(fmu).read_bytes()).hexdigest()[:32]
    cache = writable(EXTRACT_CACHE, "OBSFMU_CACHE")
    target = cache / digest
    for _ in range(_ATTEMPTS):
        lease = _lease(target)
        if lease is not None:
            try:
                os.utime(target)
                return target, lease
            except OSError:              # pruned on a system without leases: extract it again
                lease.release()
        partial = Path(tempfile.mkdtemp(prefix=f".{digest}.", dir=cache))
        try:
            unzip(Path(fmu), partial)
        except BaseException:            # refused, damaged or interrupted: nothing stays
            shutil.rmtree(partial, ignore_errors=True)
            raise
        lease = _lease(partial)          # the lock moves with the folder
        try:
            os.replace(partial, target)
        except OSError:                  # another run extracted it meanwhile (or is pruning it): lease that one
            if lease is not None:
                lease.release()
            shutil.rmtree(partial, ignore_errors=True)
            continue
        _prune(cache, keep=target)
        if lease is not None:
            return target, lease
    raise SimulationError(f"{fmu}: its folder in the extraction cache {cache} was removed {_ATTEMPTS} times "
                          f"while it was being opened (other runs pruning the cache?)")


def unzip(fmu: Path, folder: Path) -> None:
    """The entries of ``fmu`` written into ``folder``, within the limits of the module docstring;
    :class:`SimulationError` naming the limit or the damage otherwise (``folder`` may then hold a part)."""
    try:
        with zipfile.ZipFile(fmu) as archive:
            entries = archive.infolist()
            _check_entries(fmu, entries)
            written = 0
            for entry in entries:
                target = folder.joinpath(*PurePosixPath(entry.filename).parts)
                if entry.is_dir():
                    target.mkdir(parents=True, exist_ok=True)
                    continue
                target.parent.mkdir(parents=True, exist_ok=True)
                with archive.open(entry) as source, open(target, "wb") as sink:
                    while chunk := source.read(_CHUNK):
                        written += len(chunk)
                        if written > MAX_UNPACKED:
                            raise SimulationError(_too_large(fmu, f"more than {written} bytes unpacked"))
                        sink.write(chunk)
    except (zipfile.BadZipFile, zipfile.LargeZipFile, NotImplementedError, EOFError, ValueError) as exc:
        raise SimulationError(f"{fmu}: not a readable FMU archive ({exc}); nothing extracted") from None


def _check_entries(fmu: Path, entries: list) -> None:
    if len(entries) > MAX_ENTRIES:
        raise SimulationError(f"{fmu}: {len(entries)} entries; an FMU may have at most {MAX_ENTRIES} "
                              f"(fmus.master.cache.MAX_ENTRIES): refused, nothing extracted")
    total = sum(entry.file_size for entry in entries)
    if total > MAX_UNPACKED:
        raise SimulationError(_too_large(fmu, f"{total} bytes uncompressed"))
    for entry in entries:
        parts = PurePosixPath(entry.filename).parts
        if ("\\" in entry.filename or ":" in entry.filename or entry.filename.startswith("/")
                or ".." in parts or not parts):
            raise SimulationError(f"{fmu}: entry {entry.filename!r} would leave the FMU's folder: "
                                  f"refused, nothing extracted")
        if entry.file_size > RATIO_FROM and entry.file_size > MAX_RATIO * max(entry.compress_size, 1):
            raise SimulationError(f"{fmu}: entry {entry.filename} unpacks {entry.file_size} bytes from "
                                  f"{entry.compress_size} ({entry.file_size / max(entry.compress_size, 1):.0f} "
                                  f"times); an entry over {RATIO_FROM} bytes may unpack to at most {MAX_RATIO} "
                                  f"times its size (fmus.master.cache.MAX_RATIO; a zip bomb?): refused, nothing "
                                  f"extracted")


def _too_large(fmu: Path, found: str) -> str:
    return (f"{fmu}: {found}; an FMU may unpack to at most {MAX_UNPACKED} bytes (1 GiB, "
            f"fmus.master.cache.MAX_UNPACKED): refused, nothing extracted")


def _prune(cache: Path, keep: Path) -> None:
    """Remove all but the :data:`EXTRACT_CACHE_SIZE` most recently used entries (never ``keep``, nor one
    under a :class:`Lease`), and partial extractions older than :data:`ABANDONED_AFTER` seconds (a run
    killed while extracting).  Other processes prune the same cache at the same time: an entry gone
    meanwhile is skipped."""
    used, abandoned, now = [], [], wallclock.time()
    for entry in cache.iterdir():
        try:
            modified = entry.stat().st_mtime
        except OSError:
            continue
        if not entry.name.startswith("."):
            used.append((modified, entry.name))
        elif now - modified > ABANDONED_AFTER:
            abandoned.append(entry.name)
    for name in abandoned:
        shutil.rmtree(cache / name, ignore_errors=True)
    for _, name in sorted(used, reverse=True)[EXTRACT_CACHE_SIZE:]:
        if name != keep.name:
            _remove_unused(cache, name)


def _remove_unused(cache: Path, name: str) -> None:
    """Remove the entry ``name`` unless it is leased: under an exclusive lock it is renamed to a partial's
    name first (a run that opens it now finds it gone and extracts it again), then removed."""
    entry = cache / name
    if fcntl is None:
        shutil.rmtree(entry, ignore_errors=True)
        return
    try:
        fd = os.open(entry / LEASE, os.O_RDWR | os.O_CREAT, 0o600)
    except OSError:                      # gone meanwhile, or not a folder
        return
    doomed = cache / f".{name}.pruned.{uuid.uuid4().hex}"
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        os.replace(entry, doomed)
    except OSError:                      # in use (BlockingIOError), or gone meanwhile
        return
    finally:
        os.close(fd)
    shutil.rmtree(doomed, ignore_errors=True)
