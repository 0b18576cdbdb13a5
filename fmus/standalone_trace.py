"""Run one FMU's slave the way the bridge does and print every module it imported (for fmus/standalone.py).

    python -I -S -X utf8 standalone_trace.py RESOURCES SITE_DIR...

``RESOURCES`` is an FMU's resources folder; the SITE_DIRs (where numpy is) are appended to ``sys.path``,
as the standalone runtime's ``site-packages`` is.  The slave class is loaded by the FMU's own
``obsfmu_bootstrap.py`` (``runpy``, as ``bridge.c`` does), instantiated, initialized, stepped, its
values read and set, a state saved, serialized, restored, a call refused, terminated and reset.  A
call that fails is reported on stderr and the trace goes on: the modules its failure imports are
wanted too.  Output: one line ``<module name>\\t<file>`` per module with a file.  Imports nothing of
its own beyond what the bridge's interpreter imports anyway (``runpy``).
"""

import runpy
import sys


def _record(resources: str) -> dict:
    with open(f"{resources}/obsfmu_native.txt", encoding="utf-8") as file:
        lines = [line.rstrip("\n") for line in file if "=" in line and not line.startswith("#")]
    return dict(line.split("=", 1) for line in lines)


def _attempt(what: str, call, *args):
    try:
        return call(*args)
    except Exception as exc:  # noqa: BLE001 -- the trace goes on: a failure's imports are wanted too
        print(f"trace: {what}: {type(exc).__name__}: {exc}", file=sys.stderr)
        return None


def _step_size(slave) -> float:
    """The sample time of a discrete block (a parameter ``Ts``), else a small step."""
    for vr, variable in slave.vars.items():
        if variable.name == "Ts":
            values = _attempt("get Ts", slave.get_real, [vr])
            if values:
                return float(values[0])
    return 1e-3


def exercise(slave_class, resources: str) -> None:
    slave = slave_class(instance_name="trace", resources=resources, visible=False, logger=None)
    reals = [vr for vr, v in slave.vars.items() if type(v).__name__ == "Real"]
    inputs = [vr for vr in reals if slave.vars[vr].causality.name == "input"]
    outputs = [vr for vr in reals if slave.vars[vr].causality.name == "output"]
    h = _step_size(slave)
    _attempt("setup_experiment", slave.setup_experiment, 0.0, None, None)
    _attempt("enter_initialization_mode", slave.enter_initialization_mode)
    _attempt("exit_initialization_mode", slave.exit_initialization_mode)
    _attempt("set_real", slave.set_real, inputs, [0.0] * len(inputs))
    _attempt("set_real_input_derivatives", slave.set_real_input_derivatives, inputs, [1] * len(inputs),
             [0.0] * len(inputs))
    t = 0.0
    for _ in range(3):
        _attempt("do_step", slave.do_step, t, h)
        t += h
    _attempt("get_real", slave.get_real, reals)
    state = _attempt("get_fmu_state", slave.get_fmu_state, {"fmi": 2, "state": "stepComplete"})
    if state is not None:
        data = _attempt("serialize_fmu_state", slave.serialize_fmu_state, state)
        restored = _attempt("deserialize_fmu_state", slave.deserialize_fmu_state, data) if data else None
        _attempt("set_fmu_state", slave.set_fmu_state, restored or state)
        _attempt("loader_fields", slave.loader_fields, restored or state)
    plan = _attempt("batch_plan", slave.batch_plan, inputs, True, outputs)
    if plan is not None:
        _attempt("step_batched", slave.step_batched, t, h)
    _attempt("refused set_real", slave.set_real, [2**31], [0.0])     # a refusal: its message's imports
    _attempt("do_step (refused)", slave.do_step, t + 1.0, -h)
    _attempt("terminate", slave.terminate)
    slave_class(instance_name="trace-reset", resources=resources, visible=False, logger=None)


def main(resources: str, sites: list) -> None:
    sys.path.extend(sites)
    record = _record(resources)
    namespace = runpy.run_path(f"{resources}/obsfmu_bootstrap.py", None, "obsfmu_bootstrap")
    slave_class = namespace["load_slave_class"](resources, record["package"], record["slave_module"],
                                                 record["slave_class"])
    exercise(slave_class, resources)
    for name, module in sorted(sys.modules.items()):
        spec = getattr(module, "__spec__", None)
        origin = getattr(spec, "origin", None) if spec is not None else None
        if origin in (None, "frozen", "built-in"):
            origin = getattr(module, "__file__", None)
        if origin:
            print(f"{name}\t{origin}")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:])
