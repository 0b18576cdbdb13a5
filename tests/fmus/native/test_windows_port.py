"""The FMI 2.0 loader built for win64 (issue 28.7, docs/portability.md "Windows and macOS").

With Debian's MinGW-w64 (``apt-get install mingw-w64``) the loader compiles for Windows unchanged but for
``win32_dlfcn.h``: dlopen, dlsym, dlclose, dlerror and dl_iterate_phdr over LoadLibraryExA, GetProcAddress,
FreeLibrary and EnumProcessModules (the only POSIX calls it used that MinGW lacks; pthread, stat and strtok_r
come with MinGW-w64).  The DLL needs only KERNEL32 and msvcrt and exports every FMI 2.0 function and the
process-wide start guard.  Under wine (``apt-get install wine64``) a tiny C host (``win_host.c``) loads
it and instantiates an FMU whose record names a Python that is not there: the loader answers with its
clear "no usable Python" message and a NULL instance -- never a crash.  What the port still lacks
(the Windows Python finding, a bridge against python3.dll, ``binaries/win64`` in the builder): the docs.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

from fmus.native import HERE, LOADER, fmi_headers, loader_library

MINGW = "x86_64-w64-mingw32-gcc"
HOST = Path(__file__).with_name("win_host.c")
#: what the DLL may import: nothing but Windows itself and its C runtime (winpthread and libgcc linked in)
SYSTEM_DLLS = {"KERNEL32.dll", "msvcrt.dll"}


def wine() -> str | None:
    return shutil.which("wine64") or shutil.which("wine") or next(
        (str(p) for p in [Path("/usr/lib/wine/wine64")] if p.is_file()), None)


def cross_compile(source: Path, output: Path, *flags: str) -> subprocess.CompletedProcess:
    return subprocess.run([MINGW, "-O2", "-Wall", "-Werror", "-Wno-format-truncation", "-o", str(output), str(source),
                           f"-I{HERE}", f"-I{fmi_headers()}", "-pthread", "-static", *flags],
                          capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def windows_loader(tmp_path_factory) -> Path:
    if shutil.which(MINGW) is None:
        pytest.skip(f"{MINGW} is not installed (Debian: apt-get install mingw-w64)")
    dll = tmp_path_factory.mktemp("win64") / "ship_plant.dll"
    completed = cross_compile(LOADER, dll, "-shared")
    assert completed.returncode == 0, completed.stderr[-3000:]   # -Werror: not even a warning
    return dll


def pe_dump(path: Path) -> str:
    return subprocess.run(["x86_64-w64-mingw32-objdump", "-p", str(path)], capture_output=True, text=True,
                          check=True).stdout


def test_the_fmi2_loader_cross_compiles_for_win64_with_every_export(windows_loader):
    dump = pe_dump(windows_loader)
    exports = {line.split()[-1] for line in dump.split("[Ordinal/Name Pointer] Table")[1].splitlines()
               if line.strip().startswith("[")}
    linux = subprocess.run(["nm", "-D", "--defined-only", str(loader_library(2))], capture_output=True, text=True,
                           check=True).stdout
    wanted = {line.split()[-1] for line in linux.splitlines() if line.split()[-1].startswith(("fmi2", "obsfmu"))}
    assert len(wanted) >= 30 and wanted <= exports, sorted(wanted - exports)
    imports = {line.split("DLL Name:")[1].strip() for line in dump.splitlines() if "DLL Name:" in line}
    assert imports == SYSTEM_DLLS, imports


def test_under_wine_a_windows_host_gets_the_no_python_message(windows_loader, tmp_path):
    program = wine()
    if program is None:
        pytest.skip("wine is not installed (Debian: apt-get install wine64)")
    host = tmp_path / "win_host.exe"
    completed = cross_compile(HOST, host)
    assert completed.returncode == 0, completed.stderr[-3000:]
    resources = tmp_path / "fmu" / "resources"
    resources.mkdir(parents=True)
    guid = "{0b5e1c3a-28a7-4c1e-9c7b-000000000028}"
    (resources / "obsfmu_native.txt").write_text(
        f"guid={guid}\npackage=_obsfmu_0\nslave_module=_slave_x\nslave_class=x\nbridge=binaries/win64/obsfmu_bridge_cp311.dll\n"
        "python_version=3.11\npython_executable=C:/absent/python.exe\npython_library=C:/absent/python311.dll\n")
    environment = {"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "HOME": str(tmp_path),
                   "WINEPREFIX": str(tmp_path / "prefix"), "WINEDEBUG": "-all"}
    run = subprocess.run([program, str(host), str(windows_loader), f"file://{resources}", guid], cwd=tmp_path,
                         env=environment, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    assert "fmi2GetVersion: 2.0" in run.stdout
    assert "no usable Python 3.11 for this FMU" in run.stdout and "OBSFMU_PYTHON" in run.stdout, run.stdout
    assert "instance: NULL" in run.stdout
