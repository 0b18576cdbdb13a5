"""Fuzzing the system-file reader (issue 26, item 9): random TOML-ish documents and random values in
every field of a valid file give a checked system or one ParameterError line -- never another exception,
a traceback or a hang (each example within the deadline)."""

from __future__ import annotations

import json
import math
import sys
import tomllib
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from obsfmu.fmus.system.kinds import component_type
from obsfmu.fmus.system.load import parse_system
from obsfmu.fmus.system.schema import TYPES
from obsfmu.observers.checks import ParameterError

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_system_file import motor_file  # noqa: E402

FUZZ = settings(derandomize=True, max_examples=300, deadline=2000,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
GOOD = tomllib.loads(motor_file())


def check(text: str) -> None:
    try:
        parse_system(text, "fuzz.toml")
    except ParameterError as exc:
        message = str(exc)
        assert message.startswith("fuzz.toml") and "\n" not in message and "Traceback" not in message, message


TOKENS = ["[", "]", "[[", "]]", "=", '"', "'", '"""', "\n", " ", ".", ",", "{", "}", "#", "components", "plant",
          "kind", '"lti"', '"chirp"', '"luenberger"', '"expression"', "A", "B", "C", "x0", "f", "h", "name",
          '"dcmotor"', "experiment", "stop_time", "step", "connections", '"plant.y -> observer.y"', "values",
          "report", "compare", "1", "-2.5e3", "0", "1e308", "inf", "nan", "true", "false", '"x[1]"', '"\\u0007"',
          '"sin(x[1]) ** 2"', "[[1, 2], [3]]", "[1, [2]]", "{ g = 1 }", "\x00", "\x1b", "é"]


@FUZZ
@given(st.lists(st.sampled_from(TOKENS), max_size=80))
def test_random_toml_ish_documents(tokens):
    check("".join(tokens))


@FUZZ
@given(st.text(max_size=300))
def test_random_text(text):
    check(text)


# ----------------------------------------------------------------------------- random values in a valid file
EXPRESSION_TOKENS = st.sampled_from(["x[1]", "x[2]", "u[1]", "p[1]", "g", "t", "pi", "+", "-", "*", "/", "**", "(",
                                     ")", "sin(", "where(", ",", "<", "and", "1e308", "__import__", "'a'", "x.y",
                                     "lambda", "[", "]", "0", " "])
SCALARS = (st.booleans() | st.integers(min_value=-2 ** 70, max_value=2 ** 70) | st.floats(allow_nan=True)
           | st.text(max_size=20) | st.lists(EXPRESSION_TOKENS, max_size=12).map("".join)
           | st.sampled_from(["plant", "observer", "lti", "chirp", "plant.y -> observer.y", "observer.x_hat"]))
VALUES = st.recursive(SCALARS, lambda inner: st.lists(inner, max_size=5)
                      | st.dictionaries(st.sampled_from(["g", "l", "a b", "x", "kind", ""]), inner, max_size=3),
                      max_leaves=20)


def toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value) if abs(value) < 2 ** 63 else f"{float(value)!r}"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(map(toml_value, value)) + "]"
    return "{ " + ", ".join(f"{json.dumps(k)} = {toml_value(v)}" for k, v in value.items()) + " }"


def dump(data: dict) -> str:
    """The system file of ``data`` (the layout of the files: scalars first, then the tables)."""
    lines = [f"{json.dumps(k)} = {toml_value(v)}" for k, v in data.items() if not isinstance(v, dict)
             and k != "report"]
    for section in ("experiment", "values"):
        if isinstance(data.get(section), dict):
            lines += [f"[{section}]"] + [f"{json.dumps(k)} = {toml_value(v)}" for k, v in data[section].items()]
    for instance, table in data.get("components", {}).items():
        lines.append(f"[components.{json.dumps(instance)}]")
        lines += [f"{json.dumps(k)} = {toml_value(v)}" for k, v in table.items()] if isinstance(table, dict) else []
    for compare in data.get("report", {}).get("compare", []):
        lines += ["[[report.compare]]"] + [f"{json.dumps(k)} = {toml_value(v)}" for k, v in compare.items()]
    return "\n".join(lines) + "\n"


FIELDS = sorted({(instance, key) for instance, table in GOOD["components"].items() for key in table}
                | {("experiment", key) for key in GOOD["experiment"]}
                | {("", key) for key in ("name", "description", "connections")}
                | {("plant", "sample_time"), ("observer", "x_hat0"), ("reference", "sweep"), ("sensor", "cutoff_hz"),
                   ("sensor", "size"), ("sensor", "distribution"), ("reference", "t0"), ("plant", "typo"),
                   ("new", "kind")})


def mutated(field: tuple[str, str], value) -> dict:
    data = json.loads(json.dumps(GOOD))
    where, key = field
    if where == "":
        data[key] = value
    elif where == "experiment":
        data["experiment"][key] = value
    else:
        data["components"].setdefault(where, {})[key] = value
    return data


def test_the_dump_of_the_good_file_is_good():
    spec = parse_system(dump(GOOD), "fuzz.toml")
    assert list(spec.components) == ["reference", "plant", "sensor", "observer", "controller"]


@FUZZ
@given(st.sampled_from(FIELDS), VALUES)
def test_random_values_in_every_field(field, value):
    check(dump(mutated(field, value)))


@FUZZ
@given(st.lists(EXPRESSION_TOKENS, min_size=1, max_size=30).map("".join),
       st.lists(EXPRESSION_TOKENS, min_size=1, max_size=30).map("".join))
def test_random_expressions_of_an_expression_plant(f, h):
    data = json.loads(json.dumps(GOOD))
    data["components"]["pendulum"] = {"kind": "expression", "inputs": 1, "parameters": {"g": 9.81},
                                      "f": ["x[2]", f], "h": [h]}
    data["values"] = {"pendulum.u": 0.5}
    check(dump(data))


def test_huge_and_deep_expressions_are_refused_at_once():
    for text in ("x[1] + " * 200_000 + "1", "(" * 10_000 + "x[1]" + ")" * 10_000):
        data = json.loads(json.dumps(GOOD))
        data["components"]["pendulum"] = {"kind": "expression", "f": [text], "h": ["x[1]"]}
        try:
            parse_system(dump(data), "fuzz.toml")
        except ParameterError as exc:
            assert "limit" in str(exc) and "pendulum.f[1]" in str(exc)
        else:
            raise AssertionError("accepted")


component_type("lti")
KINDS = sorted(TYPES)
FIELD_NAMES = sorted({f.name for kind in KINDS for f in TYPES[kind].fields} - {"kind"})


@FUZZ
@given(st.sampled_from(KINDS), st.dictionaries(st.sampled_from(FIELD_NAMES), VALUES, max_size=6))
def test_random_components_of_every_type(kind, fields):
    data = json.loads(json.dumps(GOOD))
    data["components"]["extra"] = {"kind": kind, **fields}
    check(dump(data))


@FUZZ
@given(st.data())
def test_random_values_in_the_fields_of_one_type(data):
    kind = data.draw(st.sampled_from(KINDS))
    names = sorted(f.name for f in TYPES[kind].fields if f.name != "kind")
    fields = data.draw(st.dictionaries(st.sampled_from(names), VALUES, max_size=len(names)))
    document = json.loads(json.dumps(GOOD))
    document["components"]["extra"] = {"kind": kind, **fields}
    check(dump(document))
