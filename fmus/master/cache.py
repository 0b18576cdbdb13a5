"""The extracted FMUs, once per content: a run opens an FMU from here instead of unzipping it again."""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
import time as wallclock
from pathlib import Path

from fmpy import extract

__all__ = ["EXTRACT_CACHE", "EXTRACT_CACHE_SIZE", "ABANDONED_AFTER", "extracted"]

#: extracted FMUs, by content (``OBSFMU_CACHE`` overrides); the newest are kept
EXTRACT_CACHE = Path(os.environ.get("OBSFMU_CACHE", Path.home() / ".cache" / "obsfmu")) / "extracted"
EXTRACT_CACHE_SIZE = 64
#: a partial extraction (``.<digest>.*``) this old was left by a killed run: removed when pruning
ABANDONED_AFTER = 3600.0


def extracted(fmu: Path) -> Path:
    """The FMU unzipped once per content (sha256) into :data:`EXTRACT_CACHE` and reused.

    Unzipping every FMU afresh (its bundled code: ~100 files) cost 0.15 s of every ``obsfmu run``, plus
    compiling the bundled modules again each time.  Entries are written to a temporary sibling and renamed
    (concurrent runs never see a partial one); beyond :data:`EXTRACT_CACHE_SIZE` the least recently used go.
    """
    digest = hashlib.sha256(Path(fmu).read_bytes()).hexdigest()[:32]
    target = EXTRACT_CACHE / digest
    if target.is_dir():
        try:
            os.utime(target)
            return target
        except OSError:                  # another run pruned it just now: extract it again
            pass
    EXTRACT_CACHE.mkdir(parents=True, exist_ok=True)
    partial = Path(tempfile.mkdtemp(prefix=f".{digest}.", dir=EXTRACT_CACHE))
    extract(str(fmu), unzipdir=str(partial))
    try:
        os.replace(partial, target)
    except OSError:                      # another run extracted it meanwhile
        shutil.rmtree(partial, ignore_errors=True)
    _prune(keep=target)
    return target


def _prune(keep: Path) -> None:
    """Remove all but the :data:`EXTRACT_CACHE_SIZE` most recently used entries (never ``keep``), and
    partial extractions older than :data:`ABANDONED_AFTER` seconds (a run killed while extracting).
    Other processes prune the same cache at the same time: an entry gone meanwhile is skipped."""
    used, abandoned, now = [], [], wallclock.time()
    for entry in EXTRACT_CACHE.iterdir():
        try:
            modified = entry.stat().st_mtime
        except OSError:
            continue
        if not entry.name.startswith("."):
            used.append((modified, entry.name))
        elif now - modified > ABANDONED_AFTER:
            abandoned.append(entry.name)
    for name in abandoned + [name for _, name in sorted(used, reverse=True)[EXTRACT_CACHE_SIZE:]]:
        if name != keep.name:
            shutil.rmtree(EXTRACT_CACHE / name, ignore_errors=True)
