"""The folders obsfmu caches in, and what happens when one cannot be written.

Two caches: the extracted FMUs (``$OBSFMU_CACHE/extracted``, default ``~/.cache/obsfmu/extracted``;
:mod:`fmus.master.cache`) and the compiled binaries (``$XDG_CACHE_HOME/obsfmu/native``, default
``~/.cache/obsfmu/native``; :mod:`fmus.native`).  When one cannot be created or written (a read-only file
system, a home folder without permission) every command still works: :func:`writable` gives a private
temporary cache instead, for this process, removed when it ends, and says so once (per folder) on stderr,
naming the folder, the variable that chose it and the stand-in.
"""

from __future__ import annotations

import atexit
import errno
import os
import shutil
import sys
import tempfile
from pathlib import Path

__all__ = ["writable", "FALLBACK_ERRORS"]

#: the errors that make a cache fall back (anything else, e.g. a full disk, is reported as it is)
FALLBACK_ERRORS = (errno.EROFS, errno.EACCES, errno.EPERM)
_chosen: dict[Path, Path] = {}           # folder asked for -> the folder used
_fallback: list[Path] = []               # the private temporary cache of this process, once made


def writable(folder: Path, variable: str) -> Path:
    """``folder`` created if needed, when it can be written; else its private temporary stand-in.

    ``variable`` is the environment variable that points the cache elsewhere (named in the note together
    with ``HOME`` when it is not set)."""
    folder = Path(folder)
    if folder not in _chosen:
        try:
            folder.mkdir(parents=True, exist_ok=True)
            tempfile.TemporaryFile(dir=folder).close()
            _chosen[folder] = folder
        except OSError as exc:
            if exc.errno not in FALLBACK_ERRORS:
                raise
            _chosen[folder] = _stand_in(folder, variable, exc)
    return _chosen[folder]


def _stand_in(folder: Path, variable: str, exc: OSError) -> Path:
    if not _fallback:
        root = Path(tempfile.mkdtemp(prefix="obsfmu_cache_"))
        atexit.register(shutil.rmtree, root, ignore_errors=True)
        _fallback.append(root)
    stand_in = _fallback[0] / folder.name
    stand_in.mkdir(exist_ok=True)
    chosen_by = variable if os.environ.get(variable) else f"HOME (or {variable})"
    print(f"obsfmu: note: the cache {folder} cannot be written ({exc.strerror}; its folder is chosen by "
          f"{chosen_by}): this process caches in {stand_in} instead, removed when it ends -- point {variable} "
          f"at a writable folder to keep the cache", file=sys.stderr)
    return stand_in
