"""``fmi2GetReal`` of outputs from the slave's flat output vector (issue 14, per-call cost).

The fast path must give exactly what pythonfmu's variable-by-variable getters give, for any
order and subset of outputs, follow every step, and leave every other read (parameters, inputs,
unknown value references) to the generic path.
"""

from __future__ import annotations

import numpy as np
import pytest
from pythonfmu import Fmi2Slave
from pythonfmu.variables import Real

from obsfmu.fmus.config import design_from_config
from obsfmu.fmus.runtime.slave import BlockSlave, Refused


@pytest.fixture()
def slave(tmp_path):
    design = design_from_config({"name": "chain", "plant": {"A": [[0, 1, 0], [0, 0, 1], [0, 0, 0]],
                                                            "B": [[0], [0], [1]], "C": [[1, 0, 0]]},
                                 "observer": {"poles": [-1.0, -2.0, -3.0]}})
    observer = next(d for d in design.definitions() if d.model_name.endswith("observer"))
    (tmp_path / "observer.json").write_text(observer.to_json())

    class Observer(BlockSlave):
        definition_file = "observer.json"

    instance = Observer(instance_name="observer", resources=str(tmp_path), visible=False, logger=None)
    instance.setup_experiment(0.0)
    instance.exit_initialization_mode()
    return instance


def per_variable(slave, vrs):
    return [float(slave.vars[vr].getter()) for vr in vrs]


def test_outputs_read_from_the_flat_vector_equal_the_getters_in_any_order(slave):
    outputs = list(slave._output_offsets)
    inputs = list(slave._input_elements)
    assert len(outputs) >= 3
    for k in range(3):
        slave.set_real(inputs, [0.3 * (k + 1)] * len(inputs))
        slave.set_real_input_derivatives(inputs, [1] * len(inputs), [0.1] * len(inputs))
        assert slave.do_step(0.1 * k, 0.1)
        for vrs in (outputs, outputs[::-1], outputs[1:2], [outputs[0], outputs[-1], outputs[0]]):
            assert slave.get_real(vrs) == per_variable(slave, vrs)
    assert np.any(np.array(slave.get_real(outputs)) != 0.0)         # the estimate moved


def test_other_reads_take_the_generic_path(slave):
    output = next(iter(slave._output_offsets))
    parameter = next(vr for vr, v in slave.vars.items() if v.causality.name == "parameter" and isinstance(v, Real))
    assert slave.get_real([parameter, output]) == per_variable(slave, [parameter, output])
    assert slave.get_real([]) == []
    with pytest.raises(Refused, match="value reference 999999 does not exist"):
        slave.get_real([output, 999999])
    assert Fmi2Slave.get_real(slave, [output]) == slave.get_real([output])
