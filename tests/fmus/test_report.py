"""Figures a control engineer would publish and ``obsfmu report`` (issue 16, items 1 and 3).

One short run of every scenario (module fixture) feeds both: its figure is inspected as drawn
(matplotlib objects captured on their way to the file) and its record goes into the report,
which is then read back with a real HTML parser.
"""

from __future__ import annotations

import base64
import math
from html.parser import HTMLParser

import numpy as np
import pytest
from fmpy import read_model_description
from scipy.linalg import expm

from obsfmu.fmus import plotting, report
from obsfmu.fmus.cli import main as cli
from obsfmu.fmus.scenarios import SCENARIOS, get, run

#: short runs: enough for every panel to have data, cheap enough for the suite
SHORT = {
    "ship": dict(stop_time=0.7, step=1e-4),          # covers the paper's table (to 0.67 s)
    "ltv-ls": dict(stop_time=0.5),
    "ltv-ls-bounded": dict(stop_time=2.0),
    "uio-ftdrem": dict(stop_time=1.0),
    "discrete-gpebo": dict(),
    "state-affine-pendulum": dict(stop_time=1.0),
    "state-affine-chemostat": dict(stop_time=1.0),
}


def _inspect(fig) -> list[dict]:
    """What a reader sees of each panel: labels, limits, legend position, line styles."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    panels = []
    for ax in fig.axes:
        legend = ax.get_legend()
        panels.append({
            "ylabel": ax.get_ylabel(), "xlabel": ax.get_xlabel(), "xlim": ax.get_xlim(),
            "axes_right": ax.get_window_extent(renderer).x1,
            "legend_left": legend.get_window_extent(renderer).x0 if legend else None,
            "labels": [t.get_text() for t in legend.get_texts()] if legend else [],
            "styles": [(str(line.get_color()), line.get_linestyle(), line.get_linewidth(), str(line.get_marker()),
                        line.get_alpha()) for line in ax.get_lines()],
        })
    return panels


def _run_and_capture(name, build_dir, out, **settings):
    captured = []
    original = plotting._save

    def save(fig, targets):
        captured.append(_inspect(fig))
        original(fig, targets)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(plotting, "_save", save)
        result, summary = run(name, build_dir, **settings)
        report.save_run(out, get(name), result, summary, 1.0, build_dir)
    return result, summary, captured[0]


@pytest.fixture(scope="module")
def runs(build_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("results")
    return out, {name: _run_and_capture(name, build_dir, out, **settings) for name, settings in SHORT.items()}


def test_short_runs_cover_every_scenario():
    assert set(SHORT) == set(SCENARIOS)


# ----------------------------------------------------------------------------- figures
@pytest.mark.parametrize("name", sorted(SHORT))
def test_every_axis_has_quantity_and_unit_and_time_ends_with_the_data(runs, name):
    out, done = runs
    result, _, panels = done[name]
    for panel in panels:
        label = panel["ylabel"]
        assert label.endswith("]") and " [" in label or label.endswith("(units in legend)"), label
        if label.endswith("(units in legend)"):
            assert all(text.endswith("]") for text in panel["labels"] if not text[0].isdigit()), panel["labels"]
        assert panel["xlim"] == pytest.approx((result.time[0], result.time[-1]))
    assert panels[-1]["xlabel"] == f"time t [{get(name).time_unit}]"
    assert (out / f"{name}.png").stat().st_size > 10_000
    assert (out / f"{name}.svg").read_text().lstrip().startswith("<?xml")


@pytest.mark.parametrize("name", sorted(SHORT))
def test_legends_sit_outside_the_data_and_every_line_looks_different(runs, name):
    _, done = runs
    for panel in done[name][2]:
        assert panel["legend_left"] is not None and panel["legend_left"] >= panel["axes_right"]
        assert len(set(panel["styles"])) == len(panel["styles"]), panel["styles"]   # true vs estimate distinct


@pytest.mark.parametrize("name, column, panel", [
    ("ship", "plant.x[1]", 0), ("ship", "plant.x[2]", 1),
    ("state-affine-chemostat", "plant.x[2]", 1), ("state-affine-pendulum", "plant.x[2]", 1),
])
def test_units_come_from_the_fmus_model_description(runs, build_dir, name, column, panel):
    instance, variable = column.split(".", 1)
    model = next(m for i, m, _ in get(name).components if i == instance)
    declared = {v.name: v.unit for v in read_model_description(str(build_dir / f"{model}.fmu")).modelVariables}
    assert declared[variable]                                  # rad/s, g/L, ...
    assert runs[1][name][2][panel]["ylabel"].endswith(f"[{declared[variable]}]")


def test_the_papers_table_is_drawn_only_for_the_papers_case(runs, build_dir, tmp_path):
    _, done = runs
    assert "paper's table" in done["ship"][2][0]["labels"]
    result, summary, panels = _run_and_capture("ship", build_dir, tmp_path, stop_time=0.2, step=1e-4,
                                               overrides=[("plant", "x0[1]", 0.1)])
    assert all("paper's table" not in panel["labels"] for panel in panels)
    assert panels[0]["xlim"] == pytest.approx((0.0, 0.2))
    assert "the paper's printed table does not apply" in str(summary)
    assert "max_deviation_from_paper_table" not in summary.metrics


def test_an_overridden_ship_is_compared_with_its_own_exact_solution(build_dir, tmp_path):
    """``--set controller.K[1]=-100``: the summary's exact solution is that of K = [-100, 43]."""
    result, summary, _ = _run_and_capture("ship", build_dir, tmp_path, stop_time=0.3, step=1e-4,
                                          overrides=[("controller", "K[1]", -100.0)])
    A, B, C = np.array([[0.0, 1.0], [-2.0, 3.0]]), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])
    K, N = np.array([[-100.0, 43.0]]), np.array([[83.0], [1847.0]])      # independent of the project
    Ae = np.block([[A, -B @ K], [N @ C, A - N @ C - B @ K]])
    rows = [result.index_at(t) for t in (0.1, 0.2, 0.3)]
    exact = np.array([expm(Ae * result.time[k]) @ [0.05, 0.2, 0.0, 0.0] for k in rows])
    simulated = np.column_stack([result.vector("plant.x"), result.vector("observer.x_hat")])[rows]
    assert np.max(np.abs(simulated - exact)) < 1e-5
    assert summary.metrics["max_error_vs_exact"] < 1e-5        # against the default K it would be ~0.45
    assert "controller.K[1] = -100" in summary.reference


def test_times_never_reached_are_written_as_such(runs):
    _, done = runs
    summary = done["ltv-ls"][1]                                 # 0.5 s: nothing converges
    assert math.isinf(summary.metrics["parameter_convergence_time"])
    assert "not reached" in str(summary) and "inf" not in str(summary)


# ----------------------------------------------------------------------------- report
class _Page(HTMLParser):
    """Sections, figures, metric cells, claims, references and validation cells of the report."""

    def __init__(self):
        super().__init__()
        self.sections, self.images, self.metrics, self.texts = [], {}, {}, {}
        self.tags: set[str] = set()
        self._section = None
        self._collect = None
        self._buffer: list[str] = []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        self.tags.add(tag)
        if tag == "section":
            self._section = attrs["data-scenario"]
            self.sections.append(self._section)
        elif tag == "img":
            self.images.setdefault(self._section, []).append(attrs["src"])
        elif tag == "td" and "data-metric" in attrs:
            self._collect = ("metric", attrs["data-metric"], attrs["data-value"])
        elif attrs.get("class") in ("claim", "reference", "validation"):
            self._collect = (attrs["class"],)
        if self._collect:
            self._buffer = []

    def handle_data(self, data):
        if self._collect:
            self._buffer.append(data)

    def handle_endtag(self, tag):
        if self._collect and tag in ("td", "p"):
            text = "".join(self._buffer)
            if self._collect[0] == "metric":
                self.metrics.setdefault(self._section, {})[self._collect[1]] = (self._collect[2], text)
            else:
                self.texts.setdefault((self._section, self._collect[0]), []).append(text)
            self._collect = None


@pytest.fixture(scope="module")
def page(runs, build_dir):
    out, _ = runs
    assert cli.main(["report", "--out", str(out), "--build-dir", str(build_dir)]) == 0   # nothing left to run
    parser = _Page()
    parser.feed((out / "report.html").read_text(encoding="utf-8"))
    return parser


def test_the_report_has_every_scenario_with_its_figure(page):
    assert page.sections == list(SCENARIOS)
    for name in SCENARIOS:
        (image,) = page.images[name]
        head, data = image.split(",", 1)
        assert head == "data:image/svg+xml;base64"
        assert b"<svg" in base64.b64decode(data)


def test_the_reports_numbers_are_the_summarys(page, runs):
    _, done = runs
    for name, (_, summary, _) in done.items():
        shown = page.metrics[name]
        assert set(shown) == set(summary.metrics)
        for metric, value in summary.metrics.items():
            raw, text = shown[metric]
            assert float(raw) == value or (math.isnan(value) and math.isnan(float(raw))), (name, metric)
            assert text == report.format_metric(value)
        assert page.texts[name, "reference"] == [summary.reference] and summary.reference
        assert page.texts[name, "claim"] == [get(name).claim] and len(get(name).claim) > 200


def test_the_report_states_the_fmi_facts_and_is_self_contained(page, runs):
    out, _ = runs
    for name in SCENARIOS:
        validation = page.texts[name, "validation"]
        assert validation == ["valid (no problem reported)"] * len(get(name).components)
    html = (out / "report.html").read_text()
    assert "<script" not in html and "<link" not in html and 'src="http' not in html
    for name in SCENARIOS:
        assert f"communication step</th><td>{SHORT[name].get('step', get(name).step):g} {get(name).time_unit}" in html


def test_every_claim_is_checked_and_every_number_says_where_it_holds(page, runs):
    """Each scenario's claim has checks of metrics its summary has; every metric of every scenario has an
    interval; the page marks each check met / not met / not measured."""
    from obsfmu.fmus.claims import CHECKS, holds_over
    out, done = runs
    html = (out / "report.html").read_text()
    for name, (result, summary, _) in done.items():
        assert CHECKS[name], name
        known = set(summary.metrics) | {"max_deviation_from_paper_table"}   # ship's: only runs that cover the table
        assert {check.metric for check in CHECKS[name]} <= known, name
        for metric in summary.metrics:
            assert holds_over(metric, 1.0, "s"), (name, metric)
        section = html[html.index(f'<section id="{name}"'):]
        section = section[:section.index("</section>")]
        marks = [part.split(">")[1].split("<")[0] for part in section.split('<td class="')[1:]
                 if part.startswith(("met", "not-met", "not-measured"))]
        assert len(marks) == len(CHECKS[name]) and set(marks) <= {"met", "not met", "not measured"}, name
        assert "It holds over " in section and "not stated" not in section
