"""The compiled step kernel's image of the slave: the steps of a block in C, without entering Python (issue 39).

An FMU whose block has a kernel form (:mod:`observers.kernel_forms`: the continuous LTI plant, Luenberger observer,
state feedback and integral state feedback; the continuous expression plant and the sources whose value is an
expression, whose expressions the build compiles to C, :func:`kernel_source`; paper 001's adaptive observer with
least squares, whose functions ``A(t)``, ``L(t)``, ``f`` the build compiles, :mod:`observers.ltv.kernel`) is stepped
by the native bridge in C
(``fmus/native/kernel.h``):
``fmi2DoStep``, ``fmi2SetReal`` of inputs, ``fmi2SetRealInputDerivatives``, ``fmi2GetReal`` of inputs, outputs
and parameters, and the native one-call step.  Python keeps everything else -- instantiation and its checks,
the parameters, FMU states, logging, and every step the kernel cannot vouch for (a bad input, a value beyond
the bound: the Python path refuses it with its message).

The protocol (the bridge drives it):

* :meth:`Kernels.kernel_load` -- after initialization, the *image*: one float64 vector ``memory`` holding the
  time, the state, the inputs with their record and derivatives, the matrices, the values of the parameters;
  and an int64 ``layout`` saying where each is.  The bridge writes into ``memory`` in place.  ``None``: not
  now (not initialised, a bad input remembered, pending derivatives); ``False``: never for this instance
  (no affine form, a system file's convergence flag).  ``obsfmu build --kernels python`` (the record's
  ``kernels=python``) or ``OBSFMU_KERNELS=python`` in the environment keep the bridge from asking.
* :meth:`Kernels.kernel_store` -- before any other call reaches Python: the image written back into the
  slave and its block, so Python continues exactly where the kernel stopped (FMU states serialise as
  before, in one format: a state of one path restores in the other).
* :meth:`Kernels.kernel_matrices` -- ``Phi, G0, G1`` for a new step size (the block's own propagator).

Equal results: the kernel evaluates the block's own matrices, or its expressions and integrator operation for
operation; the Python path and the kernel agree to round-off (tests/fmus/native/test_kernels.py: 1e-12 relative).
"""

from __future__ import annotations

import numpy as np
from pythonfmu import Integer, Real

from obsfmu.observers.kernel_forms import AffineForm, ExpressionForm, PackedForm

from .common import EXTRAPOLATE, INTERPOLATE, NUMERICAL_FAULTS

__all__ = ["Kernels", "KERNEL_ABI", "HEADER", "SYMBOLS", "kernel_source"]

#: the version of the image's layout, checked by the bridge (= OBSFMU_KERNEL_ABI in fmus/native/kernel.h)
KERNEL_ABI = 4
#: the kinds of kernel (= KK_AFFINE, KK_EXPRESSION, KK_LTV, KK_LTV_PLANT, KK_NOISE_FILTER)
AFFINE, EXPRESSION, LTV, LTV_PLANT, NOISE_FILTER = 1, 2, 3, 4, 5
#: a packed form's kind -> its kernel
PACKED = {"ltv-observer": LTV, "ltv-plant": LTV_PLANT, "noise-filter": NOISE_FILTER}
#: the functions of an FMU's kernel library (= OBSFMU_KERNEL_F, _G, _L, _C, _V): an expression plant's f and h, a
#: source's value (h), paper 001's observer's and plant's f(y, t), A(t), (observer) L(t) and C(t), (plant) the
#: measurement noise v(t)
SYMBOLS = ("obsfmu_kernel_f", "obsfmu_kernel_g", "obsfmu_kernel_l", "obsfmu_kernel_c", "obsfmu_kernel_v")
#: the step sizes whose matrices the image keeps (= OBSFMU_KERNEL_SLOTS): an importer stepping t_(k+1) - t_k
#: (fmusim) alternates between a few sizes one ulp apart
SLOTS = 8
#: the fields of the layout's header, in order (kernel.h reads them by these positions)
HEADER = ("abi", "kind", "n", "m", "columns", "q", "ports", "variables", "parameters", "time", "x", "w", "d",
          "previous", "previous_time", "moving", "out", "C", "D", "e", "Phi", "G0", "G1", "h", "bound", "values", "p",
          "settings", "scratch", "size")
#: where the fields start in HEADER (after the sizes)
_FIELDS = HEADER.index("time")
#: classes of a value reference in the layout's table (after the header and the ports)
PYTHON, INPUT, OUTPUT, VALUE, INTEGER = 0, 1, 2, 3, 4

assert EXTRAPOLATE == 1 and INTERPOLATE == 2          # the modes as kernel.h reads them


class Kernels:
    """The kernel image of :class:`~fmus.runtime.slave.BlockSlave` (module docstring)."""

    _kernel: tuple | None = None      # (form, offsets, memory) of the image the bridge holds

    def kernel_load(self):
        """``(layout, memory)`` for the bridge, ``None`` (not now) or ``False`` (never: Python steps)."""
        self._kernel = None
        form = self._kernel_form()
        if form is None:
            return False
        if not self._stepping or self._bad or self._derivatives or self._block is None:
            return None
        block = self._block
        if not isinstance(form, PackedForm) and set(block.get_state()) != ({form.state} if form.state else set()):
            return False                                                   # the form must be the whole state
        return self._image(form, block)

    def _kernel_form(self) -> AffineForm | ExpressionForm | PackedForm | None:
        """The block's kernel form, or None when this FMU steps in Python."""
        if self.definition.kernels == "python":
            return None
        block = self._try_block()
        form = getattr(block, "kernel_form", None)
        form = form() if form is not None else None
        if self._step_rate and not isinstance(form, PackedForm):   # a system file's convergence flag: the packed
            return None                                            # kernel vouches for it as the Python step does
        if not isinstance(form, AffineForm) and [p.name for p in self.definition.outputs] != list(form.outputs):
            return None
        return form

    def _image(self, form: AffineForm | ExpressionForm | PackedForm, block) -> tuple[np.ndarray, np.ndarray]:
        affine, packed = isinstance(form, AffineForm), isinstance(form, PackedForm)
        n, m = form.size + 2 * packed, self._input_flat.size     # packed: + the longest step, the step's note
        columns = m + (affine and form.constant)
        ports = self.definition.inputs
        q = sum(p.size for p in self.definition.outputs)
        parameters = 0 if affine else form.parameters.size
        sizes = {"time": 1, "x": n, "w": m, "d": m, "previous": m, "previous_time": len(ports), "moving": len(ports),
                 "out": q, "C": affine * q * n, "D": affine * q * m, "e": affine * q, "Phi": affine * SLOTS * n * n,
                 "G0": affine * SLOTS * n * columns, "G1": affine * SLOTS * n * columns, "h": affine * SLOTS,
                 "bound": 1, "values": len(self.vars), "p": parameters,
                 "settings": 0 if affine else len(form.settings) if packed else 4,
                 "scratch": n + 2 * columns + m + q + 7 * n + m}      # = kernel_field_size in kernel.h
        offsets, total = {}, 0
        for name, size in sizes.items():
            offsets[name] = total
            total += size
        memory = np.zeros(total)

        def put(name, values):
            memory[offsets[name]:offsets[name] + sizes[name]] = np.ravel(values)

        put("time", self._time)
        if packed:
            put("x", [*form.pack(), getattr(block, "longest_step", 0.0), self._step_noted])
            put("settings", self._packed_settings(form))
        elif n:
            put("x", getattr(block, form.state))
        put("w", self._input_flat)
        record = self._last_inputs
        put("previous", np.concatenate([record[p.name][0] for p in ports]) if ports else [])
        put("previous_time", [record[p.name][1] for p in ports])
        if affine:
            C, D, e = self._output_matrices(form, n, m)
            put("C", C.T)                                     # column by column (kernel_product)
            put("D", D.T)
            put("e", e)
            put("h", np.nan)                                  # no matrices yet: the first step asks for them
        else:
            put("p", form.parameters)
        if isinstance(form, ExpressionForm):
            put("settings", form.settings)
        put("bound", block.magnitude_bound)
        kind = AFFINE if affine else PACKED[form.kind] if packed else EXPRESSION
        layout = [KERNEL_ABI, kind, n, m, columns, q, len(ports), len(self.vars),
                  parameters] + [offsets[f] for f in HEADER[_FIELDS:-1]] + [total]
        starts = np.cumsum([0] + [p.size for p in ports]).tolist()
        layout += starts + [int(self._modes[p.name][0]) for p in ports]
        layout += self._variable_table(memory, offsets["values"])
        self._kernel = (form, offsets, memory)
        return np.array(layout, dtype=np.int64), memory

    def _packed_settings(self, form: PackedForm) -> list[float]:
        """The packed kernel's settings in the order of its C enum (the form's): the form's values and the FMU's --
        where each input is, the system's step rate, where the longest step and the step's note are."""
        fmu = {**{f"input_{port}": self._input_slices[port].start for port in form.inputs},
               "step_rate": self._step_rate, "x_longest": form.size, "x_noted": form.size + 1, "x_size": form.size + 2}
        return [float(fmu.get(name, value)) for name, value in form.settings.items()]

    def _output_matrices(self, form: AffineForm, n: int, m: int):
        """``C, D, e`` of every output element in declaration order, ``D`` over the FMU's flat inputs."""
        columns = {}                                          # block input port -> its columns in D of the form
        start = 0
        for port in form.inputs:
            columns[port] = slice(start, start + self._input_slices[port].stop - self._input_slices[port].start)
            start = columns[port].stop
        Cs, Ds, es = [], [], []
        for port in self.definition.outputs:
            C, D, e = form.outputs[port.name]
            flat = np.zeros((len(e), m))
            for name, where in columns.items():
                flat[:, self._input_slices[name]] = D[:, where]
            Cs.append(C.reshape(len(e), n))
            Ds.append(flat)
            es.append(e)
        return np.vstack(Cs), np.vstack(Ds), np.concatenate(es)

    def _variable_table(self, memory: np.ndarray, values: int) -> list[int]:
        """Per value reference ``0..V-1``: its class and index (input element, output element, or its value
        kept at ``memory[values + vr]``: the Real and Integer parameters, fixed while stepping)."""
        inputs = self._input_positions()
        table = []
        for vr in range(len(self.vars)):
            variable = self.vars.get(vr)
            if vr in inputs:
                table += [INPUT, inputs[vr]]
            elif vr in self._output_offsets:
                table += [OUTPUT, self._output_offsets[vr]]
            elif isinstance(variable, (Real, Integer)) and variable.getter is not None:
                memory[values + vr] = variable.getter()
                table += [VALUE if isinstance(variable, Real) else INTEGER, vr]
            else:
                table += [PYTHON, 0]
        return table

    def kernel_matrices(self, h: float, slot: int) -> bool:
        """``Phi, G0, G1`` of step ``h`` into the image's ``slot``; False when the block cannot step ``h`` (the
        Python path then refuses the step, naming why)."""
        form, offsets, memory = self._kernel
        if not isinstance(form, AffineForm) or not 0 <= slot < SLOTS:
            return False
        try:
            Phi, G0, G1 = form.step(h)
        except NUMERICAL_FAULTS:
            return False
        for name, matrix in (("Phi", Phi), ("G0", G0), ("G1", G1)):
            start = offsets[name] + slot * matrix.size
            memory[start:start + matrix.size] = matrix.T.ravel()     # column by column (kernel_product)
        memory[offsets["h"] + slot] = h
        return True

    def kernel_store(self) -> None:
        """The image back into the slave and its block (the kernel stepped or took inputs since it was loaded)."""
        form, offsets, memory = self._kernel
        n, m = form.size, self._input_flat.size
        self._time = float(memory[offsets["time"]])
        if isinstance(form, PackedForm):
            x = memory[offsets["x"]:offsets["x"] + n + 2]
            form.unpack(x[:n])
            if self._step_rate:
                self._block.longest_step, self._step_noted = float(x[n]), bool(x[n + 1])
        elif n:
            setattr(self._block, form.state, memory[offsets["x"]:offsets["x"] + n].copy())
        self._input_flat[:] = memory[offsets["w"]:offsets["w"] + m]
        previous = memory[offsets["previous"]:offsets["previous"] + m]
        derivatives, record = {}, {}
        for k, port in enumerate(self.definition.inputs):
            where = self._input_slices[port.name]
            record[port.name] = (previous[where].copy(), float(memory[offsets["previous_time"] + k]))
            if memory[offsets["moving"] + k]:
                store = derivatives[port.name] = self._derivative_store[port.name]
                store[:] = memory[offsets["d"]:offsets["d"] + m][where]
        self._last_inputs, self._derivatives = record, derivatives
        self._outputs_cache, self._snapshot = None, None
        if self._step_rate:                     # the outputs as the step left them: converged vouched for
            self._outputs_cache = self._vouched(self._block.outputs(self._time, self._inputs), self._block)


def kernel_source(definition) -> str | None:
    """The C source of the FMU's kernel library -- the expressions of a continuous expression plant, or of a
    source's value -- compiled by the builder for each platform (:func:`fmus.native.kernel_library`); None when
    its kernel needs none."""
    from ..kinds import expression, ltv, noise, signals, sources
    module = {"expression-plant": expression, "signal-source": signals, ltv.OBSERVER_KIND: ltv, ltv.PLANT_KIND: ltv,
              "noise-source": noise, "added-noise": noise}.get(
        definition.kind, sources if definition.kind.removesuffix("-source") in sources.SOURCE_KINDS else None)
    if definition.kernels == "python" or module is None:
        return None
    own = getattr(module, "kernel_c_source", None)
    if own is not None and (written := own(definition)) is not None:
        return written
    from obsfmu.observers.expressions_c import c_source

    made = module.kernel_expressions(definition)
    if made is None:
        return None
    functions, names = made
    symbols = dict(zip(("f", "h", "l", "c", "v"), SYMBOLS))
    if isinstance(names, dict):
        names = {symbols[key]: value for key, value in names.items()}
    return c_source({symbols[key]: texts for key, texts in functions.items()}, names)
