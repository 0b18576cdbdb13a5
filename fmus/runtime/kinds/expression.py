"""Kind ``expression-plant``: the plant of expressions (:mod:`plants.expression`) as an FMU.

The expression texts are definition options (strings), compiled at instantiation by the whitelisted
compiler :func:`observers.expressions.compile_vector` -- never ``eval`` -- and once by the definition
function too, so a bad expression is refused at BUILD time naming its field (``f[2]``).  The named
parameters are FMU parameters of their own names (scalars, with their units), in the order of the
vector ``p`` the expressions may also index (``p[1]`` is the first name); the initial state is
``x0[i]``; ``max_substep``, ``rtol`` and ``atol`` (continuous: the sub-steps' error control), ``sample_time`` (discrete: ``x[k+1] = f``) and
``substep_budget`` are parameters.  A discrete FMU accepts any step length that is a whole number of
samples; another step is refused (fmi2Discard, a log line naming ``sample_time``).

Ports: input ``u`` (m, absent if m = 0); outputs ``y`` (q) and the true state ``x`` (n).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from obsfmu.observers.checks import ParameterError
from obsfmu.observers.expressions import CONSTANTS, FUNCTIONS, VECTORS, Names, Source, compile_vector
from obsfmu.plants.expression import DEFAULT_ATOL, DEFAULT_RTOL, ExpressionPlant

from ..definition import FmuDefinition, Parameter, Port, valid_identifier
from .linear import vector_unit
from . import register

__all__ = ["expression_plant_definition", "expression_names", "kernel_expressions"]

#: parameter names of the FMU itself, never a named parameter of the expressions
_RESERVED = {"x0", "y", "max_substep", "rtol", "atol", "sample_time", "substep_budget", "u_interpolation", "t", *VECTORS, *CONSTANTS,
             *FUNCTIONS}


def expression_names(options: Mapping) -> Names:
    """The names the expressions of an expression plant's definition ``options`` may use."""
    names = options["parameters"]
    return Names(x=len(options["f"]), u=int(options["inputs"]), p=len(names),
                 parameters={name: i for i, name in enumerate(names, start=1)})


def kernel_expressions(definition: FmuDefinition) -> tuple[dict[str, list[str]], Names] | None:
    """The compiled kernel's expressions of a continuous plant (``f``, ``h``) and their names; None for a discrete
    one (it steps in Python)."""
    if any(p.name == "sample_time" for p in definition.parameters):
        return None
    options = definition.options
    return {"f": list(options["f"]), "h": list(options["h"])}, expression_names(options)


def _compiled(options: Mapping, prefix: str = ""):
    """``(f, h)`` compiled; :class:`~observers.expressions.ExpressionError` names the field."""
    names = expression_names(options)
    return (compile_vector(options["f"], names, Source(prefix + "f")),
            compile_vector(options["h"], names, Source(prefix + "h")))


@register("expression-plant")
def _expression_plant(p, options):
    f, h = _compiled(options)
    vector = np.array([float(p[name]) for name in options["parameters"]])
    sample_time = p.get("sample_time")
    return ExpressionPlant(f, h, vector, p["x0"], int(options["inputs"]),
                           sample_time=None if sample_time is None else float(sample_time),
                           max_substep=float(p.get("max_substep", 1.0)), rtol=float(p.get("rtol", DEFAULT_RTOL)),
                           atol=float(p.get("atol", DEFAULT_ATOL)), substep_budget=float(p["substep_budget"]))


def _named_parameters(parameters: Mapping, units: Mapping, prefix: str) -> list[Parameter]:
    if not isinstance(parameters, Mapping):
        raise ParameterError(f"{prefix}parameters: expected a table of name = value, got {parameters!r}")
    unknown = sorted(set(units) - set(parameters))
    if unknown:
        raise ParameterError(f"{prefix}parameter_units: {unknown[0]!r} is not a named parameter")
    result = []
    for name, value in parameters.items():
        if not (isinstance(name, str) and valid_identifier(name)) or name in _RESERVED:
            raise ParameterError(f"{prefix}parameters: {name!r} cannot name a parameter (an identifier other "
                                 f"than {', '.join(sorted(_RESERVED))})")
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                or not np.isfinite(value):
            raise ParameterError(f"{prefix}parameters.{name}: expected a finite number, got {value!r}")
        result.append(Parameter.scalar(name, value, f"named parameter {name} of the expressions", units.get(name)))
    return result


def _units(field: str, units, size: int):
    """The units of a port or of x0 (:func:`~fmus.runtime.kinds.linear.vector_unit`), one per entry if a list."""
    if isinstance(units, (list, tuple)) and len(units) != size:
        raise ParameterError(f"{field}: expected {size} units (one per entry), got {len(units)}")
    return vector_unit(units)


def expression_plant_definition(model_name: str, f: Sequence[str], h: Sequence[str], x0, *, inputs: int = 0,
                                parameters: Mapping[str, float] | None = None,
                                parameter_units: Mapping[str, str] | None = None, sample_time: float | None = None,
                                max_substep: float = 1e-3, rtol: float = DEFAULT_RTOL, atol: float = DEFAULT_ATOL,
                                substep_budget=None, state_units=None, output_units=None,
                                input_units=None, field_prefix: str = "", description: str = "") -> FmuDefinition:
    """Plant ``dx/dt = f(t, x, u, p)`` (``sample_time`` given: ``x[k+1] = f``), ``y = h(t, x, u, p)``.

    ``f`` has one expression per state (``len(x0)``), ``h`` one per output; ``parameters`` maps the
    names the expressions use to their values (``parameter_units`` their units).  Every mistake is a
    :class:`~observers.checks.ParameterError` naming the field, prefixed by ``field_prefix``
    (``"components.pendulum."``).
    """
    x0 = np.atleast_1d(np.asarray(x0, dtype=float))
    parameters, units = dict(parameters or {}), dict(parameter_units or {})
    if isinstance(inputs, bool) or not isinstance(inputs, (int, np.integer)) or inputs < 0:
        raise ParameterError(f"{field_prefix}inputs: expected the size of u (an integer >= 0), got {inputs!r}")
    options = {"f": list(f) if not isinstance(f, str) else f, "h": list(h) if not isinstance(h, str) else h,
               "parameters": list(parameters), "inputs": int(inputs)}
    if isinstance(options["f"], list) and len(options["f"]) != x0.size:
        raise ParameterError(f"{field_prefix}f: expected {x0.size} expressions (one per entry of x0), "
                             f"got {len(options['f'])}")
    fmu_parameters = _named_parameters(parameters, units, field_prefix)
    f_compiled, h_compiled = _compiled(options, field_prefix)
    m, q, n = int(inputs), h_compiled.size, f_compiled.size
    state_unit = _units(field_prefix + "state_units", state_units, n)
    output_unit, input_unit = _units(field_prefix + "output_units", output_units, q), \
        _units(field_prefix + "input_units", input_units, m)
    fmu_parameters.append(Parameter.of("x0", x0, "initial state x(0)", state_unit))
    if sample_time is None:
        fmu_parameters.append(Parameter.scalar("max_substep", max_substep, "longest RK4 sub-step", "s"))
        fmu_parameters.append(Parameter.scalar("rtol", rtol, "relative local error tolerance of each sub-step"))
        fmu_parameters.append(Parameter.scalar("atol", atol, "absolute local error tolerance of each sub-step",
                                               state_unit if isinstance(state_unit, str) else None))
    else:
        fmu_parameters.append(Parameter.scalar("sample_time", sample_time, "sample time T: x[k+1] = f", "s"))
    fmu_parameters.append(Parameter.substep_budget(substep_budget))
    try:                                                    # refused now, named
        _expression_plant({p.name: p.array(p.value) for p in fmu_parameters}, options)
    except ParameterError as exc:
        raise ParameterError(f"{field_prefix}{exc}") from None
    law = "x[k+1] = f(t, x, u, p)" if sample_time is not None else "dx/dt = f(t, x, u, p)"
    return FmuDefinition(
        model_name=model_name,
        kind="expression-plant",
        feedthrough="u" in h_compiled.uses,
        description=description or f"plant of expressions: {law}, y = h(t, x, u, p)",
        parameters=fmu_parameters,
        inputs=[Port("u", m, "plant input u", input_unit, scalar=m == 1)] if m else [],
        outputs=[Port("y", q, "output y = h(t, x, u, p)", output_unit, scalar=q == 1),
                 Port("x", n, "true state x", state_unit)],
        options=options,
    )
