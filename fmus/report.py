"""``obsfmu report``: every scenario, its paper, its checks and the FMI facts on one HTML page.

A scenario run is saved by :func:`save_run` as files in the results directory: the figure
(``NAME.png`` and ``NAME.svg``), the summary (``NAME.txt``) and a record (``NAME.json``: the
summary's numbers, the run's settings, the FMUs and their validation).  :func:`write_report`
turns the records into ``report.html``: self-contained (figures embedded as data URIs, no
script, no network), one section per scenario with

* what the paper claims (``Scenario.claim``: our words, the paper's numbers), each number of it
  marked met / not met with the measured and the claimed value (:mod:`fmus.claims`),
* what obsfmu measures (the figure, the summary and a table of its metrics), each number with the
  interval of the run where it holds,
* the agreement with the independent monolithic reference (``Summary.reference``) and its interval,
* the FMI facts (FMUs, ``fmpy.validation`` result, step, order, coupling, master).

The results folder may come from elsewhere (or be tampered with): a record is used only if every
field has its type (:func:`load_run`), every text of it is escaped, and a figure is embedded only if
it is a file of the results folder itself (a plain name, no link leading out of it).
"""

from __future__ import annotations

import base64
import html
import json
import math
import platform
import sys
from datetime import datetime, timezone
from pathlib import Path

from .claims import CHECKS, holds_over, reference_interval, verdict
from .metrics import NOT_REACHED
from .output import replacing

__all__ = ["save_run", "has_run", "load_run", "other_runs", "write_report", "format_metric", "REPORT"]

REPORT = "report.html"
RECORD_VERSION = 1


def format_metric(value: float) -> str:
    """How a metric is shown: 6 significant digits; ``inf`` (a time never reached) as "not reached"."""
    if math.isinf(value) and value > 0:
        return NOT_REACHED
    return f"{value:.6g}"


def _fmu_facts(instance: str, path: Path) -> dict:
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu
    description = read_model_description(str(path), validate=False)
    capabilities = description.coSimulation
    flags = ("canHandleVariableCommunicationStepSize", "canInterpolateInputs", "canGetAndSetFMUstate",
             "canSerializeFMUstate")
    return {
        "instance": instance,
        "model": description.modelName,
        "file": path.name,
        "fmi_version": description.fmiVersion,
        "guid": description.guid,
        "generation_tool": description.generationTool,
        "variables": len(description.modelVariables),
        "capabilities": [flag for flag in flags if getattr(capabilities, flag, False)],
        "validation": validate_fmu(str(path)),
    }


def save_run(out_dir: Path, scenario, result, summary, wall_time: float, build_dir: Path) -> Path:
    """Write ``NAME.png``, ``NAME.svg``, ``NAME.txt`` and the record ``NAME.json`` of a finished run."""
    out_dir = Path(out_dir)
    figures = scenario.plot(result, out_dir / f"{scenario.name}.png") if scenario.plot else []
    if summary is not None:
        with replacing(out_dir / f"{scenario.name}.txt") as temporary:
            temporary.write_text(str(summary) + "\n")
    info = result.info
    models = {instance: model for instance, model, _ in scenario.components}
    record = {
        "version": RECORD_VERSION,
        "scenario": scenario.name,
        "description": scenario.description,
        "claim": scenario.claim,
        "time_unit": result.time_unit,
        "stop_time": info.stop_time if info else float(result.time[-1]),
        "step": info.step if info else float("nan"),
        "order": info.order if info else "",
        "coupling": info.coupling if info else "",
        "changed": info.changed if info else {},
        "steps": len(result.time) - 1,
        "end_time": float(result.time[-1]),
        "wall_time": wall_time,
        "summary": {"lines": summary.lines, "metrics": summary.metrics, "reference": summary.reference}
        if summary is not None else None,
        "figures": [path.name for path in figures],
        "csv": f"{scenario.name}.csv" if (out_dir / f"{scenario.name}.csv").exists() else None,
        "fmus": [_fmu_facts(instance, Path(build_dir) / f"{model}.fmu") for instance, model in models.items()],
        "written": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    }
    path = out_dir / f"{scenario.name}.json"
    with replacing(path) as temporary:
        temporary.write_text(json.dumps(record, indent=1))
    return path


_NUMBER = (int, float)
#: the fields of a record and their types: a type, or (list, item type) / (dict, key type, value type)
_FMU = {"instance": str, "model": str, "file": str, "fmi_version": str, "variables": int,
        "capabilities": (list, str), "validation": (list, str)}
_SUMMARY = {"lines": (list, str), "metrics": (dict, str, _NUMBER), "reference": str}
_RECORD = {"scenario": str, "description": str, "claim": str, "time_unit": str, "stop_time": _NUMBER,
           "step": _NUMBER, "order": str, "coupling": str, "changed": (dict, str, _NUMBER), "steps": int,
           "end_time": _NUMBER, "wall_time": _NUMBER, "figures": (list, str), "fmus": (list, _FMU)}


def _fits(value, kind) -> bool:
    """``value`` has the type ``kind`` describes (see ``_RECORD``)."""
    if isinstance(kind, dict):
        return isinstance(value, dict) and all(key in value and _fits(value[key], item) for key, item in kind.items())
    if isinstance(kind, tuple) and kind[0] is list:
        return isinstance(value, list) and all(_fits(item, kind[1]) for item in value)
    if isinstance(kind, tuple) and kind[0] is dict:
        return isinstance(value, dict) and all(_fits(k, kind[1]) and _fits(v, kind[2]) for k, v in value.items())
    return isinstance(value, kind)


def load_run(out_dir: Path, name: str) -> dict | None:
    """The record of scenario ``name`` in ``out_dir`` (None if missing, unreadable, of another version or
    not of the record's shape: a field of another type)."""
    try:
        record = json.loads((Path(out_dir) / f"{name}.json").read_text())
    except (OSError, ValueError):
        return None
    usable = (_fits(record, _RECORD) and record.get("version") == RECORD_VERSION and record["scenario"] == name
              and (record.get("summary") is None or _fits(record["summary"], _SUMMARY))
              and isinstance(record.get("csv"), (str, type(None))))
    return record if usable else None


def has_run(out_dir: Path, name: str) -> bool:
    """``out_dir`` holds a usable record of ``name`` and its figure."""
    record = load_run(out_dir, name)
    return bool(record) and all((Path(out_dir) / f).exists() for f in record["figures"])


# ----------------------------------------------------------------------------- HTML
_CSS = """
body { font-family: sans-serif; max-width: 70em; margin: 2em auto; padding: 0 1em; color: #222; line-height: 1.4; }
h1 { font-size: 1.6em; } h2 { border-bottom: 1px solid #999; margin-top: 2.5em; } h3 { font-size: 1.05em; }
table { border-collapse: collapse; margin: 0.5em 0; font-size: 0.9em; }
td, th { border: 1px solid #bbb; padding: 0.2em 0.6em; text-align: left; vertical-align: top; }
td.number { text-align: right; font-family: monospace; }
img.figure { max-width: 100%; border: 1px solid #ddd; }
pre { background: #f6f6f6; padding: 0.6em; overflow-x: auto; font-size: 0.85em; }
.note { color: #555; font-size: 0.9em; }
td.met { color: #060; font-weight: bold; } td.not-met { color: #a00; font-weight: bold; }
"""


def _e(text) -> str:
    return html.escape(str(text), quote=True)


_MEDIA = {".svg": "image/svg+xml", ".png": "image/png"}


def _inside(out_dir: Path, name: str) -> bool:
    """``name`` is a file of ``out_dir`` itself: a plain name, no link leading elsewhere."""
    path = out_dir / name
    return (Path(name).name == name and name not in (".", "..") and path.is_file()
            and path.resolve().parent == out_dir.resolve())


def _figure(out_dir: Path, record: dict) -> str:
    """The scenario's figure as a data URI: the SVG (vector) if there is one, else the PNG (only files of the
    results folder itself)."""
    candidates = [name for suffix in _MEDIA for name in record["figures"]
                  if name.endswith(suffix) and _inside(out_dir, name)]
    if not candidates:
        return '<p class="note">No figure.</p>'
    name = candidates[0]
    data = base64.b64encode((out_dir / name).read_bytes()).decode("ascii")
    return (f'<img class="figure" src="data:{_MEDIA[Path(name).suffix]};base64,{data}" data-file="{_e(name)}" '
            f'alt="figure of scenario {_e(record["scenario"])}">')


def _metrics_table(record: dict, metrics: dict) -> str:
    name, end, unit = record["scenario"], record["end_time"], record["time_unit"]
    rows = "\n".join(
        f'<tr><td>{_e(key)}</td><td class="number" data-scenario="{_e(name)}" data-metric="{_e(key)}" '
        f'data-value="{_e(repr(float(value)))}">{_e(format_metric(float(value)))}</td>'
        f'<td class="interval">{_e(holds_over(key, end, unit) or "not stated")}</td></tr>'
        for key, value in metrics.items())
    return f'<table class="metrics"><tr><th>metric</th><th>value</th><th>holds</th></tr>\n{rows}\n</table>'


def _claims_table(record: dict, metrics: dict) -> str:
    """Every number of the scenario's claim: met / not met, the measured and the claimed value."""
    checks = CHECKS.get(record["scenario"], ())
    if not checks:
        return '<p class="note">No number of this claim is checked.</p>'
    rows = []
    for check in checks:
        mark, numbers = verdict(check, metrics, record["time_unit"])
        rows.append(f'<tr><td>{_e(check.claim)}</td><td class="{mark.replace(" ", "-")}" data-check='
                    f'"{_e(check.metric)}">{_e(mark)}</td><td>{_e(numbers)}</td></tr>')
    return ('<table class="checks"><tr><th>claimed</th><th>verdict</th><th>measured / claimed</th></tr>\n'
            + "\n".join(rows) + "\n</table>")


def _fmi_table(record: dict) -> str:
    rows = []
    for fmu in record["fmus"]:
        validation = "valid (no problem reported)" if not fmu["validation"] else "INVALID: " + "; ".join(
            fmu["validation"])
        rows.append(f"<tr><td>{_e(fmu['instance'])}</td><td>{_e(fmu['file'])}</td><td>FMI {_e(fmu['fmi_version'])} "
                    f"co-simulation</td><td>{_e(fmu['variables'])}</td><td>{_e(', '.join(fmu['capabilities']))}</td>"
                    f"<td class=\"validation\">{_e(validation)}</td></tr>")
    return ("<table class=\"fmus\"><tr><th>instance</th><th>FMU</th><th>interface</th><th>variables</th>"
            "<th>capabilities</th><th>fmpy.validation</th></tr>\n" + "\n".join(rows) + "\n</table>")


def _run_facts(record: dict) -> str:
    unit = record["time_unit"]
    changed = record["changed"]
    facts = [
        ("master", f"obsfmu's fmpy-based master, {record['order']} order"),
        ("coupling", f"{record['coupling']}" + (" (inputs as straight lines over a step through "
                                                "fmi2SetRealInputDerivatives)" if record["coupling"] == "linear"
                                                else " (inputs held over a step)")),
        ("communication step", f"{record['step']:g} {unit}"),
        ("stop time", f"{record['stop_time']:g} {unit} ({record['steps']} communication steps, reached "
                      f"t = {record['end_time']:g} {unit})"),
        ("wall time of the run", f"{record['wall_time']:.1f} s"),
        ("parameters", "the scenario's own" if not changed else
         "changed: " + ", ".join(f"{k} = {v:g}" for k, v in changed.items())),
    ]
    rows = "\n".join(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in facts)
    return f'<table class="run">\n{rows}\n</table>'


def _section(out_dir: Path, record: dict) -> str:
    name = record["scenario"]
    summary = record["summary"] or {"lines": [], "metrics": {}, "reference": ""}
    files = ", ".join(f for f in [record.get("csv"), *record["figures"], f"{name}.txt"] if f)
    return f"""
<section id="{_e(name)}" class="scenario" data-scenario="{_e(name)}">
<h2>{_e(name)}</h2>
<p class="note">{_e(record['description'])}</p>
<h3>{'What the paper claims' if record['claim'] else 'What is compared'}</h3>
<p class="claim">{_e(record['claim'] or 'Your own system: the comparisons of its [[report.compare]] tables.')}</p>
{_claims_table(record, summary['metrics'])}
<h3>What obsfmu measures</h3>
<p class="note">The figure shows the whole run, t = 0 .. {_e(f"{record['end_time']:g} {record['time_unit']}")}.</p>
{_figure(out_dir, record)}
<pre class="summary">{_e(chr(10).join(summary['lines']))}</pre>
{_metrics_table(record, summary['metrics'])}
<h3>Agreement with the independent monolithic reference</h3>
<p class="reference">{_e(summary['reference'] or 'No reference check recorded.')}</p>
<p class="note">It holds {_e(reference_interval(name, record['end_time'], record['time_unit']))}.</p>
<h3>FMI facts</h3>
{_fmi_table(record)}
{_run_facts(record)}
<p class="note">Files: {_e(files)} (in the directory of this page).</p>
</section>"""


def other_runs(out_dir: Path) -> list[str]:
    """The names of the usable records in ``out_dir`` that are no paper scenario's (the runs of system
    files, ``obsfmu report --config FILE``), sorted."""
    from .scenarios import SCENARIOS
    return sorted(path.stem for path in Path(out_dir).glob("*.json")
                  if path.stem not in SCENARIOS and load_run(out_dir, path.stem))


def write_report(out_dir: Path, build_dir: Path | None = None, names=None) -> Path:
    """Write ``out_dir/report.html`` from the records of ``names`` (default: every paper scenario, then
    every other run recorded in ``out_dir``: :func:`other_runs`)."""
    from fmpy import __version__ as fmpy_version

    from .scenarios import SCENARIOS
    out_dir = Path(out_dir)
    names = list(names or [*SCENARIOS, *other_runs(out_dir)])
    records = [record for name in names if (record := load_run(out_dir, name))]
    missing = [name for name in names if not load_run(out_dir, name)]
    contents = "\n".join(f'<li><a href="#{_e(r["scenario"])}">{_e(r["scenario"])}</a>: {_e(r["description"])}</li>'
                         for r in records)
    machine = f"{platform.system()} {platform.machine()}, Python {sys.version.split()[0]}, fmpy {fmpy_version}"
    page = f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>obsfmu report</title>
<style>{_CSS}</style>
</head>
<body>
<h1>obsfmu: adaptive observers as FMI 2.0 co-simulation FMUs</h1>
<p>Every scenario below is a co-simulation of FMUs (plant, observer and, where needed, signal source or
controller) run by obsfmu's master. For each: what the paper claims, what obsfmu measures, how the
co-simulation agrees with an independent monolithic solution of the same equations, and the FMI facts.
Paper claims are paraphrased with their numbers; the papers' digests are kept outside the project.</p>
<p class="note">Written {_e(datetime.now(timezone.utc).isoformat(timespec="seconds"))} on {_e(machine)}.
{'Missing scenarios (no results): ' + _e(', '.join(missing)) if missing else ''}</p>
<ul class="contents">
{contents}
</ul>
{''.join(_section(out_dir, record) for record in records)}
</body>
</html>
"""
    path = out_dir / REPORT
    with replacing(path) as temporary:
        temporary.write_text(page, encoding="utf-8")
    return path
