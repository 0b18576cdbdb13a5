"""Exports other tools read completely (issue 17, item 3), for FMI 2.0 and FMI 3.0 FMUs.

FMU Manipulation Toolbox's ``fmucontainer`` ignores SSP parameter bindings and exposes only the
outputs the SSD connects to the system.  The export therefore writes the start values into the FMU
copies (their modelDescription, and resources/obsfmu_start.txt that their binary sets at
instantiation and reset) and declares every output on the system.  The container of the
``ltv-ls-bounded`` SSP then runs under ``fmpy.simulate_fmu`` like ``obsfmu run --master jacobi``:
the container steps its FMUs in parallel from held inputs (Jacobi), and the exported
``<port>_interpolation = 1`` makes every FMU extrapolate its inputs from the previous point --
what our Jacobi master's linear coupling does with input derivatives.
"""

import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu

from obsfmu.fmus.export import export, identifier
from obsfmu.fmus.master import Component, Session, SimulationError, System
from obsfmu.fmus.scenarios import get, run

SSD = "{http://ssp-standard.org/SSP1/SystemStructureDescription}"
SSV = "{http://ssp-standard.org/SSP1/SystemStructureParameterValues}"
STOP, STEP = 2.0, 1e-3


def fmucontainer() -> str:
    pytest.importorskip("fmu_manipulation_toolbox")
    command = shutil.which("fmucontainer", path=str(Path(sys.executable).parent)) or shutil.which("fmucontainer")
    assert command, "fmu-manipulation-toolbox is installed but its fmucontainer command is not"
    return command


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_fmu_container_of_the_ssp_reproduces_the_jacobi_master(build_dir, tmp_path, fmi_version):
    path = export(get("ltv-ls-bounded"), "ssp", tmp_path, build_dir, step=STEP, stop_time=STOP,
                  fmi_version=fmi_version)
    completed = subprocess.run([fmucontainer(), "-container", f"{path.name}:{STEP!r}", "-fmu-directory", str(tmp_path),
                                "-fmi", str(fmi_version)], capture_output=True, text=True)
    container = tmp_path / "ltv-ls-bounded.fmu"
    assert completed.returncode == 0 and container.is_file(), completed.stdout + completed.stderr
    ours, _ = run("ltv-ls-bounded", build_dir, stop_time=STOP, step=STEP, order="jacobi", fmi_version=fmi_version,
                   ramp=0)   # the container steps on the plain grid
    theirs = simulate_fmu(str(container), stop_time=STOP, step_size=STEP, output_interval=STEP)
    assert np.array_equal(theirs["time"], ours.time)
    # the configuration survived: y(0) = x0[1] = 2 of ltv-ls-bounded, not the FMU's default -3
    assert theirs["plant_y"][0] == 2.0 == ours["plant.y"][0]
    names = ["plant.y"] + [f"observer.theta_hat[{j}]" for j in range(1, 9)] + ["observer.x_hat[1]", "observer.x_hat[2]"]
    if fmi_version == 2:  # the system's outputs are the container's, one per element (identifiers) ...
        mine = np.column_stack([theirs[identifier(name)] for name in names])
    else:                 # ... or one per FMI 3.0 array
        mine = np.column_stack([theirs["plant_y"], theirs["observer_theta_hat"], theirs["observer_x_hat"]])
    deviation = np.max(np.abs(mine - np.column_stack([ours[name] for name in names])))
    assert deviation < 1e-9, deviation  # measured 4.2e-14 (FMI 2.0 and 3.0)


def ssd(path) -> ElementTree.Element:
    return ElementTree.fromstring(zipfile.ZipFile(path).read("SystemStructure.ssd"))


def test_the_ssd_declares_every_output_on_the_system(build_dir, tmp_path):
    root = ssd(export(get("ship"), "ssp", tmp_path, build_dir))
    system = root.find(f"{SSD}System")
    connectors = {c.get("name"): c.get("kind") for c in system.find(f"{SSD}Connectors")}
    outputs = {f"{instance}.{v.name}" for instance, model, _ in get("ship").components
               for v in read_model_description(str(build_dir / f"{model}.fmu")).modelVariables
               if v.causality == "output"}
    assert set(connectors) == {identifier(name) for name in outputs} and len(connectors) == len(outputs)
    assert set(connectors.values()) == {"output"} and "observer_x_hat_1" in connectors
    to_system = {(c.get("startElement"), c.get("startConnector"), c.get("endConnector"))
                 for c in system.iter(f"{SSD}Connection") if c.get("endElement") is None}
    assert {f"{e}.{n}" for e, n, _ in to_system} == outputs
    assert all(identifier(f"{e}.{n}") == end for e, n, end in to_system)
    without = ssd(export(get("ship"), "ssp", tmp_path / "lite", build_dir, system_outputs=False))
    assert all(c.get("endElement") for c in without.iter(f"{SSD}Connection"))  # for libcosim and ECOS


IDENTIFIER = r"[A-Za-z_][A-Za-z0-9_]*"


@pytest.mark.parametrize("fmi_version", [2, 3])
@pytest.mark.parametrize("name", ["ltv-ls-bounded", "ship"])
def test_the_ssd_names_are_identifiers_omsimulator_accepts(build_dir, tmp_path, name, fmi_version):
    """OMSimulator 3.0 (not installable here) refused the export: '"ltv-ls-bounded" is not a valid ident' (the model and system names)
    and 'Causality mismatch in connection: source.y -> source.y' (a system connector named ``source.y``).  Now the
    model, system, component and system-connector names are identifiers, the scenario's name is the description,
    component connectors are the FMUs' own variable names, and no connection joins a name to itself."""
    path = export(get(name), "ssp", tmp_path, build_dir, fmi_version=fmi_version)
    root = ssd(path)
    system = root.find(f"{SSD}System")
    assert root.get("description") == f"obsfmu scenario {name}"
    components = system.findall(f"{SSD}Elements/{SSD}Component")
    names = [root.get("name"), system.get("name")] + [c.get("name") for c in components] \
        + [c.get("name") for c in system.find(f"{SSD}Connectors")]
    assert all(re.fullmatch(IDENTIFIER, n) for n in names), [n for n in names if not re.fullmatch(IDENTIFIER, n)]
    for component in components:
        with zipfile.ZipFile(path) as package:
            with package.open(component.get("source")) as fmu, zipfile.ZipFile(fmu) as inner:
                variables = {v.get("name") for v in ElementTree.fromstring(inner.read("modelDescription.xml")).iter()
                             if v.tag in ("ScalarVariable", "Float64", "Int32", "Boolean")}
        assert {c.get("name") for c in component.find(f"{SSD}Connectors")} <= variables
    ends = [(f"{c.get('startElement')}.{c.get('startConnector')}",
             f"{c.get('endElement')}.{c.get('endConnector')}" if c.get("endElement") else c.get("endConnector"))
            for c in system.iter(f"{SSD}Connection")]
    assert ends and all(start != end for start, end in ends)
    system_connectors = {c.get("name") for c in system.find(f"{SSD}Connectors")}
    assert all("." not in end for start, end in ends if end in system_connectors) and system_connectors


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_fmu_copies_carry_the_start_values(build_dir, tmp_path, fmi_version):
    """A copy alone under fmpy (no start values given) starts from the exported ones."""
    path = export(get("ltv-ls-bounded"), "ssp", tmp_path, build_dir, overrides=[("plant", "x0[2]", 0.25)],
                  fmi_version=fmi_version)
    with zipfile.ZipFile(path) as package:
        package.extract("resources/ltv_ls_bounded_plant.fmu", tmp_path)
    copy = tmp_path / "resources" / "ltv_ls_bounded_plant.fmu"
    declared = {v.name: v.start for v in read_model_description(str(copy)).modelVariables}
    if fmi_version == 2:
        assert float(declared["x0[1]"]) == 2.0 and float(declared["x0[2]"]) == 0.25
    else:
        assert [float(x) for x in declared["x0"].split()] == [2.0, 0.25]
    assert int(declared["u_interpolation"]) == 1
    result = simulate_fmu(str(copy), stop_time=1e-3, step_size=1e-3)
    x = result["x"][0] if fmi_version == 3 else [result["x[1]"][0], result["x[2]"][0]]
    assert list(x) == [2.0, 0.25]
    with Session(System([Component("plant", copy, {"u": 0.0})], []), echo_log=False) as session:  # the second run resets
        runs = [session.run(1e-3, 1e-3) for _ in range(2)]
    assert all(list(r.values[0][[r.columns.index("plant.x[1]"), r.columns.index("plant.x[2]")]]) == [2.0, 0.25]
               for r in runs)
    starts = zipfile.ZipFile(copy).read("resources/obsfmu_start.txt").decode()
    assert "R 9 0.25" in starts and "I " in starts  # x0[2] is the slave's value reference 9 (FMI 2.0 numbering)


def test_fmi3_ssp_connects_whole_variables_and_binds_scalars(build_dir, tmp_path):
    root = ssd(export(get("ship"), "ssp", tmp_path, build_dir, fmi_version=3))
    connections = {(c.get("startElement"), c.get("startConnector"), c.get("endElement"), c.get("endConnector"))
                   for c in root.iter(f"{SSD}Connection") if c.get("endElement")}
    assert ("observer", "x_hat", "controller", "x_hat") in connections and len(connections) == 4
    bound = {p.get("name") for p in root.iter(f"{SSV}Parameter")}
    assert bound and all("[" not in name for name in bound)
    with pytest.raises(SimulationError, match="OSP system structures name FMI 2.0 scalar variables"):
        export(get("ship"), "osp", tmp_path / "osp", build_dir, fmi_version=3)
