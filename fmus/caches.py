"""The folders obsfmu caches in, and what happens when one cannot be written.

The caches: the extracted FMUs (``$OBSFMU_CACHE/extracted``, default ``~/.cache/obsfmu/extracted``;
:mod:`fmus.master.cache`), the compiled binaries (``$XDG_CACHE_HOME/obsfmu/native``, default
``~/.cache/obsfmu/native``; :mod:`fmus.native`), the fetched wheels (``.../obsfmu/wheels``) and the
verdicts of slow checks (``.../obsfmu/checks``, :func:`remembered`).  When one cannot be created or written (a read-only file
system, a home folder without permission) every command still works: :func:`writable` gives a private
temporary cache instead, for this process, removed when it ends, and says so once (per folder) on stderr,
naming the folder, the variable that chose it and the stand-in.
"""

from __future__ import annotations

import atexit
import errno
import hashlib
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Any, Callable

__all__ = ["writable", "FALLBACK_ERRORS", "cache_root", "obsfmu_cache", "default_build_dir", "remembered"]

#: the errors that make a cache fall back (anything else, e.g. a full disk, is reported as it is)
FALLBACK_ERRORS = (errno.EROFS, errno.EACCES, errno.EPERM)
_chosen: dict[Path, Path] = {}           # folder asked for -> the folder used
_fallback: list[Path] = []               # the private temporary cache of this process, once made


def obsfmu_cache() -> Path:
    """``$OBSFMU_CACHE`` (default :func:`cache_root`): the extracted FMUs, the API's systems and builds."""
    return Path(os.environ.get("OBSFMU_CACHE") or cache_root())


def default_build_dir(root: Path | None = None) -> Path:
    """Where FMUs are built when no ``--build-dir`` is given: the checkout's ``build/`` when obsfmu runs from its
    source tree ``root`` (default: this file's; the README's commands), else ``$OBSFMU_CACHE/build`` -- never the
    working directory."""
    root = Path(__file__).resolve().parents[1] if root is None else Path(root)
    if (root / "pyproject.toml").is_file() and (root / "fmus").is_dir():
        return root / "build"
    return obsfmu_cache() / "build"


def cache_root() -> Path:
    """``$XDG_CACHE_HOME/obsfmu`` (default ``~/.cache/obsfmu``): the folder of the native, wheel and check caches."""
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "obsfmu"


_REMEMBERED: dict[str, Any] = {}         # key -> verdict, this process


def remembered(folder: str, key: str, compute: Callable[[], Any]) -> Any:
    """``compute()`` (JSON data), kept under the SHA-256 of ``key`` in ``cache_root() / folder`` and in this process.

    For slow, deterministic checks: ``key`` must hold everything the verdict depends on (the inputs and the
    sources of the code that computes it).  The file is written atomically; an unreadable one is recomputed."""
    digest = hashlib.sha256(key.encode()).hexdigest()[:32]
    if digest in _REMEMBERED:
        return _REMEMBERED[digest]
    path = cache_root() / folder / f"{digest}.json"
    try:
        value = json.loads(path.read_text())["value"]
    except (OSError, ValueError, KeyError, TypeError):
        value = compute()
        target = writable(cache_root() / folder, "XDG_CACHE_HOME")
        with tempfile.NamedTemporaryFile("w", dir=target, suffix=".tmp", delete=False) as handle:
            json.dump({"value": value}, handle)
        os.replace(handle.name, target / path.name)
    _REMEMBERED[digest] = value
    return value


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
