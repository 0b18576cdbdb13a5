"""Per-step cost of an expression plant FMU against the same plant written by hand (issue 26: <= 1.3x).

The plant: a forced Duffing oscillator, ``x1' = x2``, ``x2' = -delta x2 - alpha x1 - beta x1^3 + gain u``,
``y = x1``, RK4 with ``max_substep`` (one sub-step per communication step by default).

* **expression**: the ``expression-plant`` kind (fmus/runtime/kinds/expression.py), its right-hand side
  compiled from text by :mod:`observers.expressions`;
* **hand-written**: a Duffing block written here on Python floats (the same RK4, ``rk4_step``), put into
  the same generic slave (fmus/runtime/slave) of the same FMU in place of the expression block -- the
  strict comparison;
* **project-style**: the same block written as the project's hand-written plants are
  (plants/state_affine.py: numpy elements in the right-hand side, the input by ``Segment.at``).

Both run through the slave's own FMI entry points as the bridge calls them (``set_real``,
``set_real_input_derivatives``, ``do_step``, ``get_real``), with every check of a step, interleaved
and the best of ``--repeats`` taken; the ratios are expression / each hand-written block per step.  The native
binary's C part (loader, bridge) costs the same for both and is left out, so the ratio is an upper
bound of what an importer sees; the absolute time per step of the expression FMU through the whole
binary (fmpy, ``fmi2DoStep``) is printed for scale.  Not asserted anywhere (a benchmark).

Run:  .venv/bin/python benchmarks/expression_plant.py [--steps N] [--repeats R] [--substeps S]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from obsfmu.fmus.builder import build_fmu
from obsfmu.fmus.runtime.kinds.expression import expression_plant_definition
from obsfmu.fmus.runtime.slave import BlockSlave
from obsfmu.observers.block import Block
from obsfmu.observers.integrators import rk4_step, substep_count

PARAMETERS = {"delta": 0.3, "alpha": -1.0, "beta": 1.0, "gain": 0.8}
F = ["x[2]", "-delta * x[2] - alpha * x[1] - beta * x[1] ** 3 + gain * u[1]"]
STEP = 1e-3


class HandDuffing(Block):
    """The Duffing oscillator written by hand: what a hand-written kind's block would be."""

    not_state = ("delta", "alpha", "beta", "gain", "max_substep")

    def __init__(self, x0, max_substep: float, delta: float, alpha: float, beta: float, gain: float):
        self.x = np.array(x0, dtype=float)
        self.max_substep = max_substep
        self.delta, self.alpha, self.beta, self.gain = delta, alpha, beta, gain
        self.input_sizes, self.output_sizes = {"u": 1}, {"y": 1, "x": 2}

    def _rhs(self, x, u: float) -> np.ndarray:
        x1, x2 = x.tolist()
        return np.array([x2, -self.delta * x2 - self.alpha * x1 - self.beta * x1 ** 3 + self.gain * u])

    def outputs(self, t, inputs):
        return {"y": self.x[:1].copy(), "x": self.x.copy()}

    def advance(self, t, h, inputs):
        u = inputs["u"]
        start, slope = float(u.start[0]), float(u.slope[0])
        count = substep_count(h, self.max_substep)
        self.x = rk4_step(lambda s, x: self._rhs(x, start + (s - t) * slope), t, self.x, h, count)


class ProjectStyleDuffing(HandDuffing):
    """The same, written as the project's hand-written plants are (plants/state_affine.py): numpy
    elements in the right-hand side, the input by ``Segment.at``."""

    def _rhs(self, x, u: float) -> np.ndarray:
        return np.array([x[1], -self.delta * x[1] - self.alpha * x[0] - self.beta * x[0] ** 3 + self.gain * u])

    def advance(self, t, h, inputs):
        u = inputs["u"]
        count = substep_count(h, self.max_substep)
        self.x = rk4_step(lambda s, x: self._rhs(x, float(u.at(s - t)[0])), t, self.x, h, count)


#: what is measured: name -> the block put into the slave (None: the FMU's own expression block)
BLOCKS = {"expression": None, "hand-written": HandDuffing, "project-style": ProjectStyleDuffing}


def _slaves(fmu: Path, substep: float) -> dict:
    """In-process slaves of the FMU: its own expression block and the hand-written ones."""
    resources = Path(extract(str(fmu))) / "resources"
    slave_class = type("duffing", (BlockSlave,), {"definition_file": "duffing.json"})
    slaves = {}
    for name, block in BLOCKS.items():
        slave = slave_class(instance_name=name, resources=str(resources), visible=False, logger=None)
        slave.setup_experiment(0.0)
        slave.enter_initialization_mode()
        if block is not None:
            slave._use_block(block([1.0, 0.0], substep, **PARAMETERS))
        slave.exit_initialization_mode()
        slaves[name] = slave
    return slaves


def _per_step(slave, steps: int, u_vr: int, outputs: list[int]) -> float:
    t0 = time.perf_counter()
    t = slave._time
    for k in range(steps):
        u = 0.5 * np.sin(1.2 * t)
        slave.set_real([u_vr], [u])
        slave.set_real_input_derivatives([u_vr], [1], [0.6 * np.cos(1.2 * t)])
        if not slave.do_step(t, STEP):
            raise RuntimeError("a step was refused")
        slave.get_real(outputs)
        t += STEP
    return (time.perf_counter() - t0) / steps


def _native_per_step(fmu: Path, steps: int, u_vr: int, outputs: list[int]) -> float:
    description = read_model_description(str(fmu))
    slave = FMU2Slave(guid=description.guid, unzipDirectory=extract(str(fmu)), instanceName="native",
                      modelIdentifier=description.coSimulation.modelIdentifier)
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    t, t0 = 0.0, time.perf_counter()
    for _ in range(steps):
        slave.setReal([u_vr], [0.5 * np.sin(1.2 * t)])
        slave.setRealInputDerivatives([u_vr], [1], [0.6 * np.cos(1.2 * t)])
        slave.doStep(t, STEP)
        slave.getReal(outputs)
        t += STEP
    elapsed = (time.perf_counter() - t0) / steps
    slave.terminate()
    slave.freeInstance()
    return elapsed


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--substeps", type=int, default=1, help="RK4 sub-steps per communication step")
    args = parser.parse_args(argv)
    substep = STEP / args.substeps
    with tempfile.TemporaryDirectory(prefix="obsfmu_expression_") as temp:
        fmu = build_fmu(expression_plant_definition("duffing", F, ["x[1]"], [1.0, 0.0], inputs=1,
                                                    parameters=PARAMETERS, max_substep=substep), temp)
        variables = {v.name: v.valueReference for v in read_model_description(str(fmu)).modelVariables}
        u_vr, outputs = variables["u"], [variables[name] for name in ("y", "x[1]", "x[2]")]
        slaves = _slaves(fmu, substep)
        best = dict.fromkeys(slaves, np.inf)
        for _ in range(args.repeats):
            for name, slave in slaves.items():
                best[name] = min(best[name], _per_step(slave, args.steps, u_vr, outputs))
        gap = max(float(np.max(np.abs(slave._block.x - slaves["expression"]._block.x))) for slave in slaves.values())
        native = _native_per_step(fmu, args.steps, u_vr, outputs)
    print(f"Duffing plant, h = {STEP:g} s, {args.substeps} RK4 sub-step(s) per step, best of {args.repeats} x "
          f"{args.steps} steps (slave entry points, in process):")
    for name, seconds in best.items():
        print(f"  {name:13s} {seconds * 1e6:8.1f} us/step")
    for name in ("hand-written", "project-style"):
        print(f"  ratio expression / {name}: {best['expression'] / best[name]:.3f} (target <= 1.3)")
    print(f"  states after the same steps differ by at most {gap:.2e}")
    print(f"  expression FMU through the native binary (fmpy): {native * 1e6:.1f} us/step")


if __name__ == "__main__":
    main()
