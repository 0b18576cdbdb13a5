"""A root file system without Python for the C importer and standalone FMUs, entered with chroot.

The root holds the importer, the manylinux2014 system libraries it and the FMUs may load (those of
:data:`fmus.standalone.SYSTEM_LIBRARIES`, copied from this machine) and the FMUs unzipped under
``/fmus``.  It is entered with ``unshare --mount --map-root-user chroot`` (or plain ``chroot`` when
user namespaces are not permitted but the process may chroot) and an empty environment.
Used by ``tests/fmus/native/test_standalone.py`` and ``benchmarks/standalone_size.py``.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

from fmpy import extract, read_model_description

from native_harness import Unzipped, system_script

#: the system set on this machine (Debian multiarch): file names of the libraries and the dynamic loader
LIBRARY_FOLDER = Path("/lib/x86_64-linux-gnu")
SYSTEM_FILES = ("libc.so.6", "libm.so.6", "libdl.so.2", "librt.so.1", "libpthread.so.0", "libgcc_s.so.1",
                "libstdc++.so.6")
LOADER = Path("/lib64/ld-linux-x86-64.so.2")


def first_of_each_kind() -> dict:
    """kind -> (scenario, instance, model, start values) of the first FMU of each block kind of the scenarios."""
    from obsfmu.fmus.scenarios import SCENARIOS
    kinds = {}
    for scenario in SCENARIOS.values():
        for item in scenario.definitions():
            definition = item[0] if isinstance(item, tuple) else item
            if definition.kind not in kinds:
                instance, start = next((i, s) for i, m, s in scenario.components if m == definition.model_name)
                kinds[definition.kind] = (scenario, instance, definition.model_name, start)
    return kinds


def alone_lines(unzipped: Unzipped, start: dict, steps: int, step: float, csv: str) -> list[str]:
    """The importer's script of one FMU run alone (inputs held at their start values) for ``steps`` steps."""
    return system_script([unzipped], [], {unzipped.instance: start}) + [
        f"cosim jacobi hold 0 {steps * step!r} {step!r} {csv}", "clear"]


def make_root(root: Path, importer: Path) -> Path:
    """``root`` with the importer (``/importer``) and the system libraries; returns ``root``."""
    (root / LIBRARY_FOLDER.relative_to("/")).mkdir(parents=True, exist_ok=True)
    (root / "lib64").mkdir(exist_ok=True)
    for name in SYSTEM_FILES:
        shutil.copy(LIBRARY_FOLDER / name, root / LIBRARY_FOLDER.relative_to("/") / name)  # follows links
    shutil.copy(LOADER, root / LOADER.relative_to("/"))
    shutil.copy(importer, root / "importer")
    (root / "out").mkdir(exist_ok=True)
    return root


def unzip(root: Path, instance: str, fmu: Path, folder: str) -> Unzipped:
    """``fmu`` unzipped in ``root/fmus/<folder>``, declared as ``instance`` with its path inside the root."""
    folder = root / "fmus" / folder
    extract(str(fmu), unzipdir=str(folder))
    return Unzipped(instance, "/" + folder.relative_to(root).as_posix(), read_model_description(str(fmu)))


def pythons(root: Path) -> list[str]:
    """Files of a Python in ``root`` outside the FMUs (there must be none): every file but the FMUs'."""
    return [p.relative_to(root).as_posix() for p in root.rglob("*")
            if "python" in p.name.lower() and p.relative_to(root).parts[0] != "fmus"]


def enter_command(root: Path) -> list[str] | None:
    """The command prefix that runs a program inside ``root``, or None when this process may not chroot."""
    unshare, chroot = shutil.which("unshare"), shutil.which("chroot")
    if chroot is None:
        return None
    candidates = ([[unshare, "--mount", "--map-root-user", chroot, str(root)]] if unshare else []) + [[chroot, str(root)]]
    for prefix in candidates:
        if subprocess.run(prefix + ["/importer"], capture_output=True, env={}).returncode in (0, 1, 2):
            return prefix  # the importer ran (without a script it only prints its usage)
    return None


def read_only_command(root: Path) -> list[str] | None:
    """Like :func:`enter_command`, with ``/fmus`` mounted read-only first (a bind mount in the new mount
    namespace); None when that is not permitted."""
    unshare, chroot, shell = shutil.which("unshare"), shutil.which("chroot"), shutil.which("sh")
    if not (unshare and chroot and shell):
        return None
    script = (f'mount --bind "$0/fmus" "$0/fmus" && mount -o remount,ro,bind "$0/fmus" && exec {chroot} "$0" "$@"')
    prefix = [unshare, "--mount", "--map-root-user", shell, "-c", script, str(root)]
    (root / "fmus").mkdir(exist_ok=True)
    probe = subprocess.run(prefix + ["/importer"], capture_output=True, env={})
    return prefix if probe.returncode in (1, 2) and b"usage" in probe.stderr else None


def run_in_root(prefix: list[str], root: Path, lines: list[str], name: str, env: dict | None = None,
                timeout: float = 600) -> subprocess.CompletedProcess:
    """Run the importer on the script ``lines`` inside ``root`` (environment: ``env``, default empty)."""
    (root / f"{name}.txt").write_text("\n".join(lines) + "\n")
    return subprocess.run(prefix + ["/importer", f"/{name}.txt"], env=env or {}, capture_output=True, text=True,
                          timeout=timeout)
