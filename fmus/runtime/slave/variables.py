"""The FMU's variables: parameters, inputs with their interpolation modes and derivatives, outputs.

Every parameter and input element is a pythonfmu variable whose getter and setter read and write
the slave's arrays; outputs are read from the block's outputs, computed once per change
(:mod:`.block`).  A ``set`` the slave cannot carry out is refused before any value is set
(:class:`~.common.Refused`); a value out of bounds is remembered and refused by the next step
(docs/faults.md).
"""

from __future__ import annotations

import numpy as np
from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real, String
from pythonfmu.enums import Fmi2Status

from ..definition import element_unit
from .common import InputMode, Refused, interpolation_parameter

__all__ = ["Variables"]


class Variables:
    """The variables of :class:`~fmus.runtime.slave.BlockSlave`: registration, get/set, input modes and derivatives."""

    def _register_variables(self) -> None:
        definition = self.definition
        for p in definition.parameters:
            self._register_array(p.element_names, self._params[p.name], Fmi2Causality.parameter,
                                 p.description, p.unit, on_set=self._parameters_changed)
        if not self._stateless():
            for port in definition.inputs:
                self._register_mode(port.name)
        for port in definition.inputs:
            references = self._register_array(port.element_names, self._inputs[port.name], Fmi2Causality.input,
                                              [port.element_description(i) for i in range(port.size)], port.unit,
                                              on_set=self._input_changed)
            self._input_elements.update({vr: (port.name, i, name)
                                         for i, (vr, name) in enumerate(zip(references, port.element_names))})
        for port in definition.outputs:
            self._register_outputs(port)

    def _register_array(self, names, store: np.ndarray, causality, description, unit, on_set) -> list[int]:
        variability = Fmi2Variability.fixed if causality == Fmi2Causality.parameter else Fmi2Variability.continuous
        references = []
        for i, name in enumerate(names):
            def setter(value, i=i, name=name):
                store[i] = value
                on_set(name, value)
            text = description[i] if isinstance(description, list) else description     # per element, or one
            variable = Real(name, causality=causality, variability=variability, description=text,
                            getter=lambda i=i: float(store[i]), setter=setter)
            self.register_variable(variable)
            references.append(variable.value_reference)
            if element_unit(unit, i):
                self._units[name] = element_unit(unit, i)
        return references

    def _register_mode(self, port: str):
        store = self._modes[port]

        def setter(value):
            store[0] = int(value)          # set_integer checked the value first

        self.register_variable(Integer(
            interpolation_parameter(port), causality=Fmi2Causality.parameter,
            variability=Fmi2Variability.fixed,
            description=f"input {port} inside a step: 0 hold, 1 extrapolate from the previous point "
                        f"(value at step start), 2 interpolate (value at step end, Gauss-Seidel)",
            getter=lambda: int(store[0]), setter=setter))

    def _register_outputs(self, port):
        for i, name in enumerate(port.element_names):
            variable = Real(name, causality=Fmi2Causality.output, variability=Fmi2Variability.continuous,
                            description=port.element_description(i),
                            getter=lambda p=port.name, i=i: self._output(p, i))
            self.register_variable(variable)
            self._output_offsets[variable.value_reference] = len(self._output_offsets)
            if element_unit(port.unit, i):
                self._units[name] = element_unit(port.unit, i)

    def _parameters_changed(self, name, value):
        self._block = None
        self._block_error = None
        self._outputs_cache = None
        self._snapshot = None

    def _input_changed(self, name, value):
        self._flag(name, value)
        if self._feedthrough:                  # other blocks' outputs do not depend on the inputs
            self._outputs_cache = None

    def _flag(self, name: str, value: float) -> None:
        """Remember an input (or input derivative) element that a step must refuse."""
        if -self._bound <= value <= self._bound:
            self._bad.pop(name, None)
        else:
            self._bad[name] = value

    def _input_positions(self) -> dict[int, int]:
        """Real input value reference -> its element's position in the flat input vector."""
        return {vr: self._input_slices[port].start + index for vr, (port, index, _) in self._input_elements.items()}

    def _variable(self, vr, kind):
        """The variable of ``vr``, of type ``kind``; :class:`Refused` otherwise."""
        variable = self.vars.get(vr)
        if variable is None:
            raise Refused(f"value reference {vr} does not exist")
        if not isinstance(variable, kind):
            raise Refused(f"{variable.name} (value reference {vr}) is not a {kind.__name__} variable")
        return variable

    def _check_writable(self, vrs, kind, values) -> None:
        """Refuse a whole ``fmi2Set*`` call before any value is set (:class:`Refused`)."""
        fixed = []
        for vr, value in zip(vrs, values):
            variable = self._variable(vr, kind)
            if variable.setter is None or variable.causality == Fmi2Causality.output:
                raise Refused(f"{variable.name} is an output; outputs cannot be set")
            if variable.causality == Fmi2Causality.parameter:
                if self._stepping:
                    fixed.append(f"{variable.name} (in use: {variable.getter():g})")
                elif kind is Integer and int(value) not in InputMode._value2member_map_:
                    raise Refused(f"{variable.name}: {value} is not 0 (hold), 1 (extrapolate) or "
                                  f"2 (interpolate); keeping {variable.getter()}")
        if fixed:
            raise Refused(f"{', '.join(fixed)}: parameters are fixed after initialization "
                          f"(fmi2ExitInitializationMode) and keep their values; set them before, "
                          f"or reset the instance")

    def _read(self, read, kind, vrs) -> list:
        """pythonfmu's getter ``read`` of ``vrs``; a value reference that does not exist or is not a
        ``kind`` variable is refused (:class:`Refused`), any other exception is a bug."""
        try:
            return read(self, vrs)
        except (KeyError, TypeError):
            for vr in vrs:
                self._variable(vr, kind)
            raise

    def set_real(self, vrs, values):
        elements = self._input_elements
        targets = [elements.get(vr) for vr in vrs]
        if None in targets:
            self._check_writable(vrs, Real, values)
            super().set_real(vrs, values)
            return
        inputs, bound, bad = self._inputs, self._bound, self._bad   # the hot path: inputs, every step
        for (port, index, name), value in zip(targets, values):
            inputs[port][index] = value
            if -bound <= value <= bound:
                if bad:
                    bad.pop(name, None)
            else:
                bad[name] = value
        if self._feedthrough:                  # other blocks' outputs do not depend on the inputs
            self._outputs_cache = None

    def set_integer(self, vrs, values):
        self._check_writable(vrs, Integer, values)
        super().set_integer(vrs, values)

    def set_boolean(self, vrs, values):
        self._check_writable(vrs, Boolean, values)
        super().set_boolean(vrs, values)

    def set_string(self, vrs, values):
        self._check_writable(vrs, String, values)
        super().set_string(vrs, values)

    def get_real(self, vrs):
        """``fmi2GetReal``: outputs only (every step) from one flat vector of the cached outputs;
        anything else variable by variable through pythonfmu's getters."""
        key = tuple(vrs)
        positions = self._output_plans.get(key, False)
        if positions is False:
            offsets = self._output_offsets
            positions = np.array([offsets[vr] for vr in key], dtype=np.intp) \
                if key and all(vr in offsets for vr in key) else None
            if len(self._output_plans) < 64:
                self._output_plans[key] = positions
        flat = None if positions is None else self._flat_outputs()
        if flat is None or flat.size != len(self._output_offsets):   # (a block with a wrong output size)
            return self._read(Fmi2Slave.get_real, Real, vrs)
        return flat[positions].tolist()

    def _flat_outputs(self) -> np.ndarray:
        """Every output element in declaration order, as one vector (rebuilt when the outputs change)."""
        cache = self._outputs_cache
        if cache is None:
            first = self.definition.outputs[0]
            self._output(first.name, 0)          # computes the outputs, or refuses naming why
            cache = self._outputs_cache
        source, flat = self._flat
        if source is not cache:
            flat = np.concatenate([np.asarray(cache[p.name], dtype=float).ravel() for p in self.definition.outputs])
            self._flat = cache, flat
        return flat

    def get_integer(self, vrs):
        return self._read(Fmi2Slave.get_integer, Integer, vrs)

    def get_boolean(self, vrs):
        return self._read(Fmi2Slave.get_boolean, Boolean, vrs)

    def get_string(self, vrs):
        return self._read(Fmi2Slave.get_string, String, vrs)

    def set_real_input_derivatives(self, vrs, orders, values):
        """First time derivatives of inputs for the next step (``fmi2SetRealInputDerivatives``).

        They override the port's ``<port>_interpolation`` mode for that step
        only: ``u(t + s) = u(t) + s du``; after the step the input holds
        ``u(t) + h du`` (what direct-feedthrough outputs at ``t + h`` see).
        Higher orders are ignored with a warning.  NaN, inf and huge values make the next
        step refuse (like inputs).
        """
        elements, derivatives = self._input_elements, self._derivatives
        unknown = [vr for vr in vrs if vr not in elements]
        if unknown:
            raise Refused(f"value reference {unknown[0]} is not a real input")
        for vr, order, value in zip(vrs, orders, values):
            if order != 1:
                self.log(f"input derivative of order {order} ignored (only order 1 is used)", Fmi2Status.warning)
                continue
            port, index, name = elements[vr]
            if port not in derivatives:
                store = derivatives[port] = self._derivative_store[port]   # no allocation per step
                store[:] = 0.0
            derivatives[port][index] = value
            if not -self._bound <= value <= self._bound or self._bad:
                self._flag(f"der({name})", value)

    def clear_input_derivatives(self, vrs) -> None:
        """Forget the input derivatives of the ports of ``vrs`` (the FMI 3.0 binary: the slopes it gave a
        step from the intermediate update belong to that step; a discarded step gives them back)."""
        for vr in vrs:
            port, _, _ = self._input_elements[vr]
            if self._derivatives.pop(port, None) is not None:
                for name in self._element_names[port]:
                    self._bad.pop(f"der({name})", None)
