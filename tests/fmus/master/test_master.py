"""Master algorithm: wiring errors are clear, feedthrough is resolved, results are complete."""

import numpy as np
import pytest

from obsfmu.fmus.master import Component, Connection, SimulationError, System, cosimulate
from obsfmu.fmus.scenarios.ship import SCENARIO


def ship_system(fmus, connections=None, start=None):
    components = [Component(i, fmus[m], {**given, **(start or {}).get(i, {})}) for i, m, given in SCENARIO.components]
    return System(components, connections if connections is not None else list(SCENARIO.connections))


@pytest.mark.parametrize("connections, message", [
    ([Connection("plant.y", "ghost.y")], "unknown instance 'ghost'"),
    ([Connection("plant.x", "observer.y")], "2 outputs vs 1 inputs"),
    ([Connection("plant.y", "observer.yy")], "observer.yy: no such input; did you mean y"),
    ([Connection("plant.u", "observer.u")], "plant.u: is a input, expected an output"),
    ([Connection("plant.y", "observer.y"), Connection("plant.y", "observer.y")], "observer.y: connected twice"),
    ([Connection("plant", "observer.y")], "expected 'instance.variable'"),
])
def test_wiring_errors(ship_fmus, connections, message):
    with pytest.raises(SimulationError, match=message.replace("(", r"\(")):
        cosimulate(ship_system(ship_fmus, connections), 0.01, 0.001)


def test_an_unconnected_input_is_an_error_naming_it_unless_given(ship_fmus):
    """Forgetting ``controller.u -> observer.u`` left the ship observer reading u = 0 (0.48 A off in a
    user's DC motor): now an error naming the input; an explicit start value makes it deliberate."""
    connections = [c for c in SCENARIO.connections if c.target != "observer.u"]
    with pytest.raises(SimulationError, match=r"^observer.u is not connected: connect it or give it a start value"):
        cosimulate(ship_system(ship_fmus, connections), 0.01, 0.001)
    result = cosimulate(ship_system(ship_fmus, connections, start={"observer": {"u": 0.0}}), 0.01, 0.001)
    assert result.time[-1] == pytest.approx(0.01)
    without_r = [Component(i, ship_fmus[m]) for i, m, _ in SCENARIO.components]
    with pytest.raises(SimulationError, match=r"^controller.r is not connected"):
        cosimulate(System(without_r, list(SCENARIO.connections)), 0.01, 0.001)


def test_bad_run_settings(ship_fmus):
    system = ship_system(ship_fmus)
    with pytest.raises(SimulationError, match="order: 'sideways'"):
        cosimulate(system, 0.1, 0.01, order="sideways")
    with pytest.raises(SimulationError, match="stop_time: must be after"):
        cosimulate(system, 0.0, 0.01)
    with pytest.raises(SimulationError, match="no such variable"):
        cosimulate(ship_system(ship_fmus, start={"plant": {"x9[1]": 1.0}}), 0.01, 0.001)


def test_feedthrough_is_consistent_at_every_communication_point(ship_fmus):
    for order in ("gauss-seidel", "jacobi"):
        result = cosimulate(ship_system(ship_fmus, start={"observer": {"x_hat0[1]": 0.01}}), 0.05, 1e-3, order=order)
        u = result["controller.u"]
        expected = -(398.0 * result["observer.x_hat[1]"] + 43.0 * result["observer.x_hat[2]"])
        np.testing.assert_allclose(u, expected, rtol=1e-12, atol=1e-15)


def test_last_step_lands_on_the_stop_time(ship_fmus):
    result = cosimulate(ship_system(ship_fmus), 0.0105, 1e-3)
    assert result.time[-1] == pytest.approx(0.0105) and len(result.time) == 12
    assert np.all(np.diff(result.time) > 0)


def test_discarded_step_reports_the_fmu_message(ship_fmus):
    system = ship_system(ship_fmus, start={"observer": {"N[1]": -1.0, "N[2]": 0.0}})
    with pytest.raises(SimulationError, match="N: not Hurwitz"):
        cosimulate(system, 0.01, 0.001, echo_log=False)


def test_the_extract_cache_skips_entries_another_process_removed(ship_fmus, tmp_path, monkeypatch):
    """Concurrent runs (``obsfmu all --jobs N``, other users) prune one cache: an entry that vanishes
    between listing and ``stat`` (here a dangling link) is skipped, and the cache stays bounded; a
    partial extraction an hour old (a killed run's) goes, one in progress stays."""
    import os

    from obsfmu.fmus.master import cache

    folder = tmp_path / "extracted"
    folder.mkdir()
    monkeypatch.setattr(cache, "EXTRACT_CACHE", folder)
    monkeypatch.setattr(cache, "EXTRACT_CACHE_SIZE", 2)
    (folder / "removed-meanwhile").symlink_to(tmp_path / "nowhere")
    for age in range(3):
        (folder / f"old{age}").mkdir()
        os.utime(folder / f"old{age}", (1000 + age, 1000 + age))
    (folder / ".abandoned.x").mkdir()                         # left by a run killed while extracting
    os.utime(folder / ".abandoned.x", (1000, 1000))
    (folder / ".extracting.y").mkdir()                        # another run extracting now
    path = cache.extracted(ship_fmus["ship_plant"])
    assert (path / "modelDescription.xml").is_file()
    kept = sorted(entry.name for entry in folder.iterdir() if entry.is_dir() and not entry.is_symlink())
    assert kept == sorted([path.name, "old2", ".extracting.y"])


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_closing_a_session_leaves_another_of_the_same_fmus_running(build_dir, fmi_version):
    """Each FMU library is loaded once per session and unloaded once when it closes: closing one session
    must not unload the binaries another one still steps (fmpy's freeInstance unloads them already; a
    second unload crashed the process at the next call of the other session)."""
    from obsfmu.fmus.master import Session
    from obsfmu.fmus.scenarios import ensure_fmus
    fmus = ensure_fmus(SCENARIO, build_dir, fmi_version=fmi_version)
    with Session(ship_system(fmus), echo_log=False) as first:
        alone = first.run(0.005, 1e-3)
        with Session(ship_system(fmus), echo_log=False) as second:
            second.run(0.005, 1e-3)
        again = first.run(0.005, 1e-3)
    np.testing.assert_array_equal(again.values, alone.values)


_OTHER_RUN_PRUNES = """
import sys
from pathlib import Path
from obsfmu.fmus.master import cache
root = Path(sys.argv[1])
for n in range(cache.EXTRACT_CACHE_SIZE + 1):
    (root / f"newer-{n}").mkdir()
cache._prune(root, keep=root / "newer-0")
"""


def test_a_session_keeps_its_extracted_fmus_while_other_runs_prune_the_cache(ship_fmus, tmp_path, monkeypatch):
    """Sweeps met ``plant: reset failed ...; FMU says: fmi2Reset: FileNotFoundError: ... resources/<model>.json``:
    fmi2Reset creates the slave again from the extracted folder, and other runs on the machine (a test suite
    extracts hundreds of FMUs) pruned the least recently used entries -- the folders of a session open for
    minutes.  An open session's folders stay, in this process and in another; closed, they may go."""
    import subprocess
    import sys

    from obsfmu.fmus.master import Session, cache

    folder = tmp_path / "extracted"
    monkeypatch.setattr(cache, "EXTRACT_CACHE", folder)
    with Session(ship_system(ship_fmus), echo_log=False) as session:
        first = session.run(0.005, 1e-3)
        used = sorted(entry.name for entry in folder.iterdir() if not entry.name.startswith("."))
        assert len(used) == len(SCENARIO.components), used
        for n in range(cache.EXTRACT_CACHE_SIZE + 1):               # newer entries of other FMUs
            (folder / f"other-{n}").mkdir()
        cache._prune(folder, keep=folder / "other-0")
        again = session.run(0.005, 1e-3)                            # fmi2Reset: the slaves read resources/ again
        assert all((folder / name / "modelDescription.xml").is_file() for name in used)
        np.testing.assert_array_equal(again.values, first.values)
        subprocess.run([sys.executable, "-c", _OTHER_RUN_PRUNES, str(folder)], check=True, timeout=120)
        assert all((folder / name / "modelDescription.xml").is_file() for name in used)
        np.testing.assert_array_equal(session.run(0.005, 1e-3).values, first.values)
    cache._prune(folder, keep=folder / "newer-0")
    assert not any((folder / name).exists() for name in used), "closed, its entries are the oldest: pruned"
    assert not [entry.name for entry in folder.iterdir() if ".pruned." in entry.name]


def test_an_fmu_of_another_guid_is_one_error_naming_it(ship_fmus, tmp_path):
    """Issue 37: a cached FMU whose modelDescription names another GUID ended in fmpy's bare 'Failed to
    instantiate model' traceback."""
    import re
    import zipfile

    from obsfmu.fmus.master import Component, SimulationError, System, cosimulate
    with zipfile.ZipFile(ship_fmus["ship_plant"]) as archive:
        items = {name: archive.read(name) for name in archive.namelist()}
    items["modelDescription.xml"] = re.sub(rb'guid="[^"]*"', b'guid="{00000000-0000-0000-0000-000000000000}"',
                                           items["modelDescription.xml"], count=1)
    other = tmp_path / "ship_plant.fmu"
    with zipfile.ZipFile(other, "w") as archive:
        for name, data in items.items():
            archive.writestr(name, data)
    with pytest.raises(SimulationError, match=f"plant: instantiating {re.escape(str(other))} failed .*GUID "
                                              r"\{00000000-0000-0000-0000-000000000000\} is not this FMU's"):
        cosimulate(System([Component("plant", other, {"u": 0.0})], []), 0.01, 1e-3, echo_log=False)
