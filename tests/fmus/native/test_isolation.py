"""Each FMU runs the code bundled in it, whatever else the process has loaded (issue 12, item 3).

The bundled code lives under ``resources/_obsfmu_<hash of the code>/`` and is imported from there
without touching ``sys.path`` (fmus/bundle.py, fmus/native/bootstrap.py).
"""

import json
import shutil
import subprocess
import sys
import sysconfig
import textwrap

import pytest

from obsfmu.fmus.builder import PROJECT_ROOT, build_fmu
from obsfmu.fmus.runtime.kinds.signals import source_definition
from obsfmu.fmus.scenarios import ensure_fmus, get

#: appended to plants/signals.py of a copy of the project: that copy's sources output 1000 more
VARIANT = """

_variant_call = Waveform.__call__
Waveform.__call__ = lambda self, t: _variant_call(self, t) + 1000.0  # the code variant of the test
"""


def python(script: str, *args: str, flags: tuple[str, ...] = ()) -> dict:
    """Run ``script`` in a fresh interpreter; it prints one JSON line."""
    command = [sys.executable, *flags, "-c", textwrap.dedent(script), *args]
    completed = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert completed.returncode == 0, completed.stdout[-3000:] + completed.stderr[-3000:]
    return json.loads(completed.stdout.splitlines()[-1])


@pytest.fixture(scope="module")
def variants(tmp_path_factory):
    """``variant_source.fmu`` built from this checkout (y = 0.5) and from a changed copy (y = 1000.5)."""
    root = tmp_path_factory.mktemp("variants")
    original = build_fmu(source_definition("variant_source", offset=0.5), root / "original")
    copy = root / "project"
    shutil.copytree(PROJECT_ROOT / "obsfmu", copy / "obsfmu", ignore=shutil.ignore_patterns("__pycache__"))
    for package in ("observers", "plants", "fmus"):     # installed as obsfmu.<package>
        shutil.copytree(PROJECT_ROOT / package, copy / "obsfmu" / package, ignore=shutil.ignore_patterns("__pycache__"))
    with open(copy / "obsfmu" / "plants" / "signals.py", "a") as handle:
        handle.write(VARIANT)
    built = python("""
        import json, sys
        sys.path.insert(0, sys.argv[1])
        from obsfmu import fmus
        assert fmus.__file__.startswith(sys.argv[1]), fmus.__file__  # the copy, not this checkout
        from obsfmu.fmus.builder import build_fmu
        from obsfmu.fmus.runtime.kinds.signals import source_definition
        print(json.dumps(str(build_fmu(source_definition("variant_source", offset=0.5), sys.argv[2]))))
    """, str(copy), str(root / "variant"))
    return str(original), built


def test_two_code_variants_in_one_process(variants, monkeypatch):
    """The host imports its own fmus/plants first; each FMU, alive together or one after the other, runs its code
    (its Python code: the source's steps on the Python path, not in its compiled kernel, issue 39)."""
    monkeypatch.setenv("OBSFMU_KERNELS", "python")
    original, variant = variants
    result = python("""
        import json, sys
        import obsfmu.fmus.runtime.kinds.signals, obsfmu.plants.signals   # the host's own project code
        path_before, plain_before = list(sys.path), {m for m in sys.modules if m.split(".")[0] in
                                                      ("obsfmu", "fmus", "observers", "plants", "pythonfmu")}
        from fmpy import extract, read_model_description, simulate_fmu
        from fmpy.fmi2 import FMU2Slave

        def first_output(path):  # simulate_fmu extracts to a temporary folder and deletes it afterwards
            return float(simulate_fmu(path, stop_time=0.01, output_interval=0.01)["y"][0])

        values = [first_output(sys.argv[2]), first_output(sys.argv[1]), first_output(sys.argv[2])]
        alive = []
        for path in sys.argv[1:]:
            description = read_model_description(path)
            slave = FMU2Slave(guid=description.guid, unzipDirectory=extract(path), instanceName="both",
                              modelIdentifier=description.coSimulation.modelIdentifier)
            slave.instantiate()
            slave.setupExperiment(startTime=0.0)
            slave.enterInitializationMode()
            slave.exitInitializationMode()
            alive.append((slave, {v.name: v.valueReference for v in description.modelVariables}))
        for slave, vr in alive:
            slave.doStep(0.0, 0.01)
        values += [slave.getReal([vr["y"]])[0] for slave, vr in alive]
        plain_after = {m for m in sys.modules if m.split(".")[0] in ("obsfmu", "fmus", "observers", "plants", "pythonfmu")}
        print(json.dumps({"values": values, "path_unchanged": sys.path == path_before,
                          "plain_unchanged": plain_after == plain_before,
                          "packages": sorted(m for m in sys.modules if m.startswith("_obsfmu_") and "." not in m)}))
    """, original, variant)
    assert result["values"] == [1000.5, 0.5, 1000.5, 0.5, 1000.5]
    assert result["path_unchanged"] and result["plain_unchanged"]
    assert len(result["packages"]) == 2  # one package per code version


def test_observers_of_two_kinds_one_after_the_other(build_dir):
    """Issue 12: simulate_fmu(ship_observer) then simulate_fmu(ltv_ls_observer) failed with
    "No module named 'fmus.runtime.kinds.ltv'" -- the second FMU ran the first one's copy of the code."""
    paths = [ensure_fmus(get("ship"), build_dir)["ship_observer"], ensure_fmus(get("ltv-ls"), build_dir)["ltv_ls_observer"]]
    result = python("""
        import json, sys
        path_before = list(sys.path)
        from fmpy import simulate_fmu
        outputs = []
        for path in sys.argv[1:]:
            result = simulate_fmu(path, stop_time=0.01, output_interval=0.005)
            outputs.append(len(result))
        plain = sorted(m for m in sys.modules if m.split(".")[0] in ("obsfmu", "fmus", "observers", "plants", "pythonfmu"))
        print(json.dumps({"outputs": outputs, "path_unchanged": sys.path == path_before, "plain": plain}))
    """, *map(str, paths), flags=("-I",))
    assert result["outputs"] == [3, 3] and result["path_unchanged"] and result["plain"] == []


def test_user_modules_are_bundled_relocated_too(tmp_path):
    """A user's ``"module:function"`` module, importing a project module, runs from the FMU alone."""
    from obsfmu.fmus.runtime.kinds.gpebo import generator_plant_definition

    user = tmp_path / "usermodel.py"
    user.write_text("from plants.gpebo import sine\n\n\ndef doubled(y):\n    return 2.0 * sine(y)\n")
    plain = build_fmu(generator_plant_definition("plain_plant"), tmp_path / "fmus")
    doubled = build_fmu(generator_plant_definition("user_plant", f="usermodel:doubled"), tmp_path / "fmus",
                        extra_modules=[user])
    result = python("""
        import json, sys
        sys.path.append(sys.argv[1])  # packages only: no .pth files, so no editable obsfmu
        from fmpy import simulate_fmu
        final = [simulate_fmu(path, stop_time=5.0, step_size=1.0, output_interval=1.0)["x[1]"][-1]
                 for path in sys.argv[2:]]
        modules = sorted(m for m in sys.modules if m.endswith("usermodel") or m.split(".")[0] in ("plants", "fmus"))
        print(json.dumps({"final": final, "modules": modules}))
    """, sysconfig.get_paths()["purelib"], str(plain), str(doubled), flags=("-I", "-S"))
    assert result["final"][0] != result["final"][1]  # the user's function is the one used
    assert [m.split(".", 1)[1] for m in result["modules"]] == ["usermodel"], result["modules"]
