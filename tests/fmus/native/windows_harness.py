"""Windows hosts under wine for the win64 FMUs (test_windows.py, benchmarks/windows_budgets.py).

* :class:`Wine`: a wine prefix of the test's own (``WINEPREFIX`` in a temporary folder, ``WINEDEBUG=-all``), and
  programs run in it with no standard input (the Windows CPython cannot start its standard streams without one);
* :func:`windows_importer`: ``importer.c`` cross-compiled with MinGW-w64 -- the suite's C host, for Windows;
* :func:`windows_fmpy`: **fmpy for Windows** -- the Windows embeddable CPython of the FMUs' Python version
  (:func:`fmus.native.windows.embeddable`) with fmpy's and its dependencies' Windows wheels, fetched once by
  ``pip download`` into the wheel cache.  A Windows FMI importer written by others, as a user on Windows runs it.

Paths of this machine become Windows paths on wine's drive ``Z:`` (the root folder): :func:`windows_path`.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

from obsfmu.fmus.native import MINGW, fmi_headers

HERE = Path(__file__).parent
#: the Windows wheels of fmpy for Windows (pinned: what the tests measured)
FMPY_WHEELS = ("fmpy==0.3.32", "numpy==2.1.3", "lxml==6.1.3", "msgpack==1.2.4", "attrs==26.1.0")


def wine() -> str | None:
    """The wine loader for 64-bit programs, or None (Debian: apt-get install wine64)."""
    found = shutil.which("wine64") or shutil.which("wine")
    return found or next((str(p) for p in [Path("/usr/lib/wine/wine64")] if p.is_file()), None)


def windows_path(path) -> str:
    """A path of this machine as wine's programs name it: ``Z:/tmp/x``."""
    return "Z:" + str(Path(path).resolve())


class Wine:
    """A wine prefix of its own; :meth:`run` runs a Windows program in it."""

    def __init__(self, folder: Path):
        self.program = wine()
        Path(folder).mkdir(parents=True, exist_ok=True)
        self.prefix = Path(folder) / "prefix"
        self.environment = {"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "HOME": str(folder),
                            "WINEPREFIX": str(self.prefix), "WINEDEBUG": "-all", "LANG": "C.UTF-8",
                            # a crash (e.g. a ucrtbase function wine 8 lacks) ends the program at once instead
                            # of starting winedbg, which waits for nobody in a test and hangs until the timeout
                            "WINEDLLOVERRIDES": "winedbg.exe=d"}

    def run(self, *arguments, timeout: float = 900, env: dict | None = None) -> subprocess.CompletedProcess:
        return subprocess.run([self.program, *map(str, arguments)], env={**self.environment, **(env or {})},
                              stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=timeout)

    def close(self) -> None:
        """Stop the prefix's wineserver (it would linger for a few seconds)."""
        server = shutil.which("wineserver") or "/usr/lib/wine/wineserver64"
        if Path(server).exists():
            subprocess.run([server, "-k"], env=self.environment, capture_output=True, timeout=60)


def cross_compile(source: Path, output: Path, *flags: str) -> subprocess.CompletedProcess:
    return subprocess.run([MINGW, "-O2", "-Wall", "-Werror", "-Wno-format-truncation", "-o", str(output),
                           str(source), f"-I{HERE.parent.parent.parent / 'fmus' / 'native'}", f"-I{fmi_headers()}",
                           "-pthread", "-static", *flags], capture_output=True, text=True, timeout=300)


def windows_importer(folder: Path) -> Path:
    """``importer.c`` as a Windows program (links nothing but KERNEL32 and msvcrt)."""
    program = Path(folder) / "importer.exe"
    completed = cross_compile(HERE / "importer.c", program, "-lm")
    assert completed.returncode == 0, completed.stderr[-3000:]
    return program


def windows_fmpy(folder: Path) -> Path:
    """``python.exe`` of fmpy for Windows in ``folder``: the embeddable CPython of the FMUs' Python version and
    the Windows wheels of :data:`FMPY_WHEELS` unpacked into its ``Lib/site-packages`` (listed in its ``._pth``)."""
    from obsfmu.fmus.native import registry, windows
    home = Path(folder) / "python"
    shutil.copytree(windows.embeddable(), home)
    wheels = registry.cache_folder() / f"test-fmpy-win64-cp{sys.version_info.major}{sys.version_info.minor}"
    if len(list(wheels.glob("*.whl"))) < len(FMPY_WHEELS):
        subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:",
                        "--platform", "win_amd64", "--python-version", windows.python_version(),
                        "--implementation", "cp", "-d", str(wheels), *FMPY_WHEELS],
                       check=True, capture_output=True, text=True, timeout=900)
    site = home / "Lib" / "site-packages"
    for wheel in sorted(wheels.glob("*.whl")):
        with zipfile.ZipFile(wheel) as archive:
            archive.extractall(site)
    pth = next(home.glob("python3*._pth"))
    pth.write_text(f"{pth.stem}.zip\n.\nLib\\site-packages\n")
    return home / "python.exe"
