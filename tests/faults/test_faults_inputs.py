"""Unbounded inputs (issue 29, finding 6): an FMU archive and a serialized FMU state are refused at once
beyond their stated limits, with the limit in the message, and leave nothing behind.

* a zip bomb (a real FMU plus a huge zero-filled entry) given to the master / ``obsfmu run --build-dir``:
  one line naming the limit, exit 2, nothing in the extraction cache (``fmus.master.cache``);
* a serialized state beyond ``MAX_STATE_BYTES`` with a valid header, through fmpy: fmi2Error naming the
  limit, memory bounded (no copy of it), the instance usable (``fmus.runtime.state_format``, the binary).
"""

from __future__ import annotations

import re
import shutil
import struct
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from obsfmu.fmus.master import SimulationError, cache
from obsfmu.fmus.runtime import state_format
from obsfmu.fmus.scenarios import ensure_fmus, get

ROOT = Path(__file__).resolve().parents[2]
MiB = 1 << 20


def _with_entry(fmu: Path, folder: Path, name: str, size: int) -> Path:
    """A copy of ``fmu`` in ``folder`` with a zero-filled entry of ``size`` bytes (ZIP_DEFLATED: ~1000:1)."""
    folder.mkdir(parents=True, exist_ok=True)
    copy = shutil.copy(fmu, folder / fmu.name)
    with zipfile.ZipFile(copy, "a", zipfile.ZIP_DEFLATED) as archive, \
            archive.open(name, "w", force_zip64=True) as entry:
        for _ in range(size // MiB):
            entry.write(bytes(MiB))
    return Path(copy)


@pytest.fixture
def empty_cache(tmp_path, monkeypatch):
    folder = tmp_path / "cache" / "extracted"
    monkeypatch.setattr(cache, "EXTRACT_CACHE", folder)
    return folder


def _left_in(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir()) if folder.is_dir() else []


def test_a_zip_bomb_fmu_is_refused_by_the_cli_at_once_and_leaves_nothing(build_dir, tmp_path):
    """The audit's case, smaller: 64 MiB of zeros (~64 kB zipped) in a real FMU of --build-dir; before,
    it was all unpacked into the cache (4.1 GB from 4.4 MB), exit 0."""
    fmus = ensure_fmus(get("ship"), build_dir)
    bombs = tmp_path / "build"
    for path in fmus.values():
        shutil.copy(path, bombs / path.name) if bombs.is_dir() else (bombs.mkdir(), shutil.copy(path, bombs))
    _with_entry(fmus["ship_plant"], bombs, "resources/padding.bin", 64 * MiB)
    store = tmp_path / "store"
    environment = {**__import__("os").environ, "OBSFMU_CACHE": str(store)}
    # given to the master, the bomb is refused before anything of it is extracted
    done = subprocess.run([sys.executable, "-c", "import sys; from obsfmu.fmus.master import Component, System, "
                           "cosimulate; cosimulate(System([Component('plant', sys.argv[1], {'u': 0.0})], []), 0.01, "
                           "1e-3)", str(bombs / "ship_plant.fmu")], capture_output=True, text=True, cwd=ROOT,
                          env=environment, timeout=300)
    assert done.returncode == 1, done.stderr
    assert "ship_plant.fmu: entry resources/padding.bin unpacks 67108864 bytes" in done.stderr
    assert f"at most {cache.MAX_RATIO} times" in done.stderr and "nothing extracted" in done.stderr
    assert not any(p.name.startswith(".") or p.stat().st_size > MiB
                   for p in (store / "extracted").rglob("*")), _left_in(store / "extracted")
    # in --build-dir it has no build record (not the file obsfmu built there): rebuilt with a note, never run
    done = subprocess.run([sys.executable, "-m", "obsfmu", "run", "ship", "--build-dir", str(bombs),
                           "--stop-time", "0.01"], capture_output=True, text=True, cwd=ROOT, env=environment,
                          timeout=300)
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    assert f"{bombs / 'ship_plant.fmu'}: no build record" in done.stderr
    with zipfile.ZipFile(bombs / "ship_plant.fmu") as archive:
        assert "resources/padding.bin" not in archive.namelist()


@pytest.mark.parametrize("limit, match", [
    ("MAX_UNPACKED", r"\d+ bytes uncompressed; an FMU may unpack to at most 8388608 bytes"),
    ("MAX_ENTRIES", r"\d+ entries; an FMU may have at most 50 "),
])
def test_an_fmu_beyond_the_size_or_entry_limit_is_refused_before_anything_is_written(
        ship_fmus, tmp_path, empty_cache, monkeypatch, limit, match):
    """The limits are read from the archive's directory first: nothing is unpacked."""
    monkeypatch.setattr(cache, limit, 8 * MiB if limit == "MAX_UNPACKED" else 50)
    monkeypatch.setattr(cache, "MAX_RATIO", 10 ** 6)
    fmu = _with_entry(ship_fmus["ship_plant"], tmp_path / "in", "resources/padding.bin", 16 * MiB)
    with pytest.raises(SimulationError, match=match):
        cache.extracted(fmu)
    assert _left_in(empty_cache) == []


def test_a_header_that_lies_about_the_size_cannot_unpack_more(ship_fmus, tmp_path, empty_cache):
    """The central directory says 1000 bytes, the data holds 16 MiB of zeros: no more than declared is
    unpacked (zipfile stops there, the running count is the second guard), the entry is refused as damaged
    (its CRC) and nothing is left."""
    fmu = Path(shutil.copy(ship_fmus["ship_plant"], tmp_path / "lying.fmu"))
    name = "resources/padding.bin"
    with zipfile.ZipFile(fmu, "a", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr(name, bytes(16 * MiB))
    data = bytearray(fmu.read_bytes())
    at = data.find(b"PK\x01\x02")                  # the central directory entry of the padding
    while data[at + 46:at + 46 + len(name)] != name.encode():
        at = data.find(b"PK\x01\x02", at + 1)
    struct.pack_into("<I", data, at + 24, 1000)      # its uncompressed size
    fmu.write_bytes(bytes(data))
    with zipfile.ZipFile(fmu) as archive:
        assert archive.getinfo("resources/padding.bin").file_size == 1000
    with pytest.raises(SimulationError, match="not a readable FMU archive .*nothing extracted"):
        cache.extracted(fmu)
    assert _left_in(empty_cache) == []


def test_the_python_and_the_c_limit_of_a_state_agree():
    header = (ROOT / "fmus" / "native" / "obsfmu_native.h").read_text()
    shift = re.search(r"#define OBSFMU_MAX_STATE_BYTES \(\(size_t\)(\d+) << (\d+)\)", header)
    assert shift and int(shift[1]) << int(shift[2]) == state_format.MAX_STATE_BYTES


def test_a_state_beyond_the_limit_is_refused_before_reading_it():
    """In Python (a slave without the binary): the size first, the checksum before any decoding."""
    oversized = _valid_header(state_format.MAX_STATE_BYTES + 1)
    with pytest.raises(state_format.StateFormatError, match=f"at most {state_format.MAX_STATE_BYTES} "
                                                            r"\(64 MiB.*refused before reading it"):
        state_format.unpack(oversized, "ship_plant {x}")
    bad_payload = state_format.pack("m g", {"x": 1.0})
    with pytest.raises(state_format.StateFormatError, match="checksum"):
        state_format.unpack(bad_payload[:-9] + b"a" + bad_payload[-8:], "m g")   # a forged array tag


def _valid_header(size: int, identity: bytes = b"ship_plant {x}") -> bytearray:
    data = bytearray(size)
    struct.pack_into("<8sHHIQ", data, 0, state_format.MAGIC, state_format.FORMAT_VERSION, 0, len(identity),
                     size - 56 - len(identity))
    data[56:56 + len(identity)] = identity
    return data


_HUGE_STATE = r"""
import ctypes, resource, struct, sys
sys.path[:0] = [sys.argv[2]]
from faults_support import Probe
from obsfmu.fmus.runtime.state_format import FORMAT_VERSION, MAGIC, MAX_STATE_BYTES
probe = Probe(sys.argv[1])
before = probe.state_bytes()
size = MAX_STATE_BYTES + 4096
buffer = (ctypes.c_char * size)()                   # the importer's buffer, allocated before measuring
identity = before[56:56 + struct.unpack_from("<I", before, 12)[0]]
header = struct.pack("<8sHHIQ", MAGIC, FORMAT_VERSION, 0, len(identity), size - 56 - len(identity))
ctypes.memmove(buffer, header, len(header))
ctypes.memmove(ctypes.addressof(buffer) + 56, identity, len(identity))
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
state = ctypes.c_void_p()
status = probe.call(probe.slave.fmi2DeSerializeFMUstate, probe.slave.component, buffer, size, ctypes.byref(state))
grown = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - peak
usable = probe.step(0.01)
print(status, grown, usable, probe.messages())
"""


def test_a_huge_state_with_a_valid_header_is_refused_at_once_with_bounded_memory(ship_fmus):
    """The audit's case (2 GB took 4.2 GB more memory and 21 s before the checksum said no), at the limit
    + 4 KiB: fmi2Error naming the limit, the peak memory of the process grows by less than 16 MiB (the
    bytes are never copied: before, by at least two copies of them), and the instance steps on."""
    done = subprocess.run([sys.executable, "-c", _HUGE_STATE, str(ship_fmus["ship_plant"]), str(ROOT / "tests")],
                          capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    status, grown_kib, usable, messages = done.stdout.strip().split(" ", 3)
    assert int(status) == 3, messages
    assert f"{state_format.MAX_STATE_BYTES + 4096} bytes; an obsfmu FMU state has at most " \
           f"{state_format.MAX_STATE_BYTES} (64 MiB)" in messages
    assert int(grown_kib) < 16 * 1024, f"peak memory grew by {int(grown_kib) / 1024:.0f} MiB"
    assert int(usable) == 0, messages
