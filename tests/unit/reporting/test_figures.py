"""Figures: well-formed SVG read back with ElementTree, labelled axes with units, the series each panel draws, no line
above the point budget, decimation, determinism."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import re
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
import svgutil
from hypothesis import given, settings, strategies as st
from locations import ROOT_DIR

from wmrid.core.errors import UsageError
from wmrid.model.base_params import direct_recovery
from wmrid.model.dynamics import (
    THETA0_NAMES,
    THETA0_UNITS,
    RegressorForm,
    base_parameters,
    intermediate_parameters,
    named_base,
)
from wmrid.model.robot import BUILTIN_ROBOTS
from wmrid.pipeline.identify import identify
from wmrid.reporting import convergence_figures, decimate, figures, fit_figures
from wmrid.reporting.decimate import MAX_POINTS, decimate_for_display
from wmrid.reporting.svg_artists import Line, Text
from wmrid.reporting.svg_draw import limits
from wmrid.reporting.svg_style import MISSING
from wmrid.sim.simulate import simulate

ROOT = ROOT_DIR


def _run(trajectory: str):
    r = BUILTIN_ROBOTS["paper"]
    sim = simulate(r.reference, r.nominal, trajectory=trajectory, duration=10)
    log = SimpleNamespace(t=sim.t, eta=sim.eta, tau=sim.tau, source="sim", notes=())
    truth = named_base(base_parameters(r.reference))  # as in the simulator's truth file
    return sim, log, identify(log, r), truth


@pytest.fixture(scope="module")
def run():
    sim, log, result, truth = _run("sinusoid")
    return SimpleNamespace(sim=sim, log=log, result=result, truth=truth)


def _model_speeds(log):
    """A stand-in for a model's predicted speeds: the measured ones, slightly off."""
    return 1.02 * np.asarray(log.eta) + 0.01


def _all_figures(run):
    return {
        "log_overview": figures.build_log_overview(run.log),
        "path": figures.build_path_figure(run.sim.pose),
        "estimates": convergence_figures.build_estimates_figure(run.result, run.truth),
        "errors": convergence_figures.build_estimates_figure(run.result, run.truth, error_mode=True),
        "residuals": fit_figures.build_residuals_figure(run.result),
        "excitation": fit_figures.build_excitation_figure(run.result),
        "convergence": convergence_figures.build_base_convergence_figure(run.result, run.truth),
        "speed_fit": fit_figures.build_speed_fit_figure(run.log.t, run.log.eta, _model_speeds(run.log), [97.1, 95.0]),
        "correlation": fit_figures.build_correlation_figure(run.result.form.base_names, run.result.theta0_cov),
    }


@pytest.fixture(scope="module")
def built(run):
    return _all_figures(run)


# --------------------------------------------------------------------------------------------------
# Decimation


def _check_decimation(t, y, max_points):
    td, yd = decimate_for_display(t, y, max_points)
    assert len(td) == len(yd) <= max(max_points, 0)
    assert td[0] == t[0]
    assert td[-1] == t[-1]
    idx = np.searchsorted(t, td)
    assert np.array_equal(t[idx], td)  # a subset of the samples ...
    assert np.all(np.diff(idx) > 0)  # ... in their order
    np.testing.assert_array_equal(y[idx], yd)
    if len(t) > max_points:
        edges = decimate._bin_edges(len(t), max_points)
        assert edges[0] == 1
        assert edges[-1] == len(t) - 1
        assert len(edges) - 1 <= (max_points - 2) // 2
        for a, b in itertools.pairwise(edges):
            kept = yd[(idx >= a) & (idx < b)]
            assert np.nanmin(y[a:b]) in kept
            assert np.nanmax(y[a:b]) in kept
    return td, yd


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(2, 3000),
    max_points=st.integers(4, 500),
    seed=st.integers(0, 2**32 - 1),
)
def test_decimation_bounded_keeps_ends_and_every_bins_extremes(n, max_points, seed):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.1, 1.0, n))
    y = rng.standard_normal(n).cumsum()
    y[rng.integers(0, n, 3)] += rng.choice([-50.0, 50.0], 3)  # spikes
    _check_decimation(t, y, max_points)


def test_decimation_leaves_short_series_alone():
    t = np.arange(10.0)
    td, yd = decimate_for_display(t, t**2, 10)
    np.testing.assert_array_equal(td, t)
    np.testing.assert_array_equal(yd, t**2)


def test_decimation_keeps_a_one_sample_spike_in_a_million():
    t = np.arange(1_000_000) * 1e-3
    y = np.sin(t)
    y[654_321] = 40.0
    y[123_457] = -40.0
    td, yd = _check_decimation(t, y, MAX_POINTS)
    assert len(td) <= MAX_POINTS
    assert 40.0 in yd
    assert -40.0 in yd


def test_decimation_with_nan():
    t = np.arange(1000.0)
    y = np.sin(t / 50)
    y[100:130] = np.nan  # a whole bin of NaN keeps one NaN: a gap in the drawn line
    y[500] = np.nan
    td, yd = decimate_for_display(t, y, 100)
    assert len(td) <= 100
    assert np.isnan(yd).any()
    assert np.nanmax(yd) == np.nanmax(y)


def test_decimation_rejects_bad_input():
    with pytest.raises(UsageError):
        decimate_for_display(np.arange(10.0), np.arange(9.0), 100)
    with pytest.raises(UsageError):
        decimate_for_display(np.arange(10.0), np.arange(10.0), 3)


# --------------------------------------------------------------------------------------------------
# Figures: the objects


def _labelled(panel):
    """A panel's labelled artists by label."""
    return {a.label: a for a in panel.artists if a.label}


def _below(fig):
    """The labels of the legend below the panels."""
    return [entry[2] for entry in fig.below]


def _svg(fig):
    return svgutil.parse(figures.render(fig))


def test_line_data_within_point_budget(built):
    longest = 0
    for name, fig in built.items():
        for panel in fig.visible:
            for line in (a for a in panel.artists if isinstance(a, Line)):
                assert len(line.x) == len(line.y) <= MAX_POINTS, f"{name}: {line.label!r} has {len(line.x)} points"
                longest = max(longest, len(line.x))
        for polyline in svgutil.polylines(_svg(fig)):  # drawn: simplified, never more
            assert len(svgutil.points(polyline)) <= MAX_POINTS, name
    assert longest > MAX_POINTS // 2  # the logs (10001 samples) were long enough to need decimating


@pytest.mark.parametrize(
    ("name", "render"),
    [
        ("log_overview", lambda run, fmt: figures.log_overview(run.log, fmt=fmt)),
        ("path", lambda run, fmt: figures.path_figure(run.sim.pose, fmt=fmt)),
        ("estimates", lambda run, fmt: convergence_figures.estimates_figure(run.result, run.truth, fmt=fmt)),
        (
            "errors",
            lambda run, fmt: convergence_figures.estimates_figure(run.result, run.truth, error_mode=True, fmt=fmt),
        ),
        ("residuals", lambda run, fmt: fit_figures.residuals_figure(run.result, fmt=fmt)),
        ("excitation", lambda run, fmt: fit_figures.excitation_figure(run.result, fmt=fmt)),
        ("convergence", lambda run, fmt: convergence_figures.base_convergence_figure(run.result, run.truth, fmt=fmt)),
        (
            "speed_fit",
            lambda run, fmt: fit_figures.speed_fit_figure(
                run.log.t, run.log.eta, _model_speeds(run.log), [97.1, 95], fmt
            ),
        ),
        (
            "correlation",
            lambda run, fmt: fit_figures.correlation_figure(run.result.form.base_names, run.result.theta0_cov, fmt),
        ),
    ],
)
def test_renders_svg_only(run, name, render):
    svg = render(run, "svg")
    root = svgutil.parse(svg)  # well-formed
    width, height = float(root.get("width")), float(root.get("height"))
    assert root.get("viewBox") == f"0 0 {root.get('width')} {root.get('height')}"  # scales to the page
    assert 700 <= width <= 1800
    assert 300 <= height <= 1000
    assert svgutil.panels(root)
    with pytest.raises(UsageError, match="svg"):
        render(run, "png")


def test_render_default_is_svg_deterministic_and_rejects_other_formats(run, built):
    svg = figures.render(built["log_overview"])
    assert svg.startswith(b"<?xml")
    assert figures.render(figures.build_log_overview(run.log)) == svg  # no date, no random ids
    with pytest.raises(UsageError, match="must be svg"):
        figures.render(built["log_overview"], "pdf")


def test_log_overview(built, run):
    fig = built["log_overview"]
    top, bottom = fig.panels
    assert top.y.label == "wheel torque (N m)"
    assert bottom.y.label == "wheel speed (rad/s)"
    assert bottom.x.label == "time since first sample (s)"
    assert fig.sharex
    assert _below(fig) == ["right wheel", "left wheel"]
    root = _svg(fig)
    drawn = svgutil.panels(root)
    for panel in drawn:  # one unbroken line per wheel, in the wheels' colours
        assert [p.get("stroke") for p in svgutil.polylines(svgutil.data(panel))] == ["#1f77b4", "#ff7f0e"]
    assert svgutil.tick_labels(drawn[0], "x") == []  # the time axis is labelled once, under the lower panel
    assert svgutil.tick_labels(drawn[1], "x") == [str(k) for k in range(11)]
    assert svgutil.legend_texts(root) == ["right wheel", "left wheel"]
    pwm = SimpleNamespace(t=run.log.t + 1.7e9, eta=run.log.eta, tau=run.log.tau, source="x", effort_unit="PWM")
    fig = figures.build_log_overview(pwm)
    assert fig.panels[0].y.label == "wheel effort (PWM)"
    assert limits(fig.visible, fig.sharex)[1][0][0] == 0.0  # epoch stamps drawn from the first sample


def test_special_characters_in_a_name_make_well_formed_xml(run):
    odd = 'PWM <&> "1"'
    log = SimpleNamespace(t=run.log.t[:100], eta=run.log.eta[:100], tau=run.log.tau[:100], source="a&b<c>",
                          effort_unit=odd)  # fmt: skip
    root = svgutil.parse(figures.log_overview(log))
    assert f"wheel effort ({odd})" in svgutil.texts(root)
    names = ["m<1>", "a&b", '"q"']
    root = svgutil.parse(fit_figures.correlation_figure(names, np.eye(3)))
    assert set(names) <= set(svgutil.texts(root))


def test_path_figure(built, run):
    fig = built["path"]
    (ax,) = fig.panels
    assert (ax.x.label, ax.y.label) == ("x (m)", "y (m)")
    assert ax.equal
    ((xlim, ylim),) = limits(fig.visible)
    assert (xlim[1] - xlim[0]) / ax.box[2] == pytest.approx((ylim[1] - ylim[0]) / ax.box[3])  # equal aspect
    artists = _labelled(ax)
    assert list(artists) == ["path", "start", "end"]
    assert (artists["start"].shape, artists["end"].shape) == ("o", "s")
    assert (artists["start"].x[0], artists["start"].y[0]) == tuple(run.sim.pose[0, :2])
    assert (artists["end"].x[0], artists["end"].y[0]) == tuple(run.sim.pose[-1, :2])
    assert svgutil.legend_texts(_svg(fig)) == ["path", "start", "end"]
    assert figures.build_path_figure(None) is None
    assert figures.path_figure(None) is None
    with pytest.raises(UsageError):
        figures.build_path_figure(np.zeros((5, 1)))


def _units_ok(label: str) -> bool:
    return any(u in label for u in ("(rad/s²)/(N m)", "1/rad", "1/s", "rad/s²"))


def test_estimates_figure(built, run):
    fig = built["estimates"]
    p = run.result.form.n_columns
    assert p == 7
    assert len(fig.visible) == 2 * p
    truth_theta = intermediate_parameters(np.array([run.truth[n] for n in THETA0_NAMES]), run.result.form)
    for n, ax in enumerate(fig.visible):
        i, k = divmod(n, p)
        assert _units_ok(ax.y.label), ax.y.label
        assert convergence_figures._subscript(f"{i + 1}{k + 1}") in ax.title
        lines = _labelled(ax)
        assert set(lines) == {"estimate", "start value", "true value"}
        assert lines["start value"].dash == "--"
        assert lines["true value"].dash == ":"
        ratio = lines["true value"].value / truth_theta[i, k]
        scale = 10.0 ** round(-np.log10(ratio))  # 1 unless the label says 10^n
        assert ratio * scale == pytest.approx(1.0)
        assert (scale == 1.0) == (_display_scale(ax.y.label) == 1.0)
        assert lines["estimate"].y[-1] * scale == pytest.approx(truth_theta[i, k], rel=1e-3, abs=1e-6)
    assert all(ax.x.label == "time (s)" for ax in fig.visible[p:])
    assert fig.sharex
    # the whole truth file is accepted as well as its "parameters" table
    whole = json.loads((ROOT / "sample_logs" / "paper_sinusoid.csv.truth.json").read_text())
    np.testing.assert_allclose(convergence_figures.true_theta(whole, run.result.form), truth_theta, rtol=1e-12)
    with pytest.raises(UsageError, match="Fd2"):
        convergence_figures.true_theta({"m11": 1.0}, run.result.form)
    no_truth = convergence_figures.build_estimates_figure(run.result)
    assert set(_labelled(no_truth.panels[0])) == {"estimate", "start value"}
    root = _svg(fig)
    assert len(svgutil.panels(root)) == 2 * p
    for panel in svgutil.panels(root):  # the estimate, and the start value dashed, the truth dotted
        inside = svgutil.data(panel)
        assert len(svgutil.polylines(inside)) >= 1
        rules = [e.get("stroke-dasharray") for e in inside.iter(f"{svgutil.NS}path") if e.get("stroke-dasharray")]
        assert len(rules) == 2


def test_estimation_error_figure(built, run):
    fig = built["errors"]
    for ax in fig.visible:
        assert _units_ok(ax.y.label)
        assert ax.title.startswith("θ̃")
        lines = _labelled(ax)
        assert set(lines) == {"zero error", "error of estimate", "error of the start value"}
        err = lines["error of estimate"].y
        start_err = lines["error of the start value"].value
        assert abs(err[-1]) < 1e-2 * max(abs(start_err), 1e-12) or abs(err[-1]) < 1e-6
    with pytest.raises(UsageError, match="truth"):
        convergence_figures.build_estimates_figure(run.result, error_mode=True)


def test_estimates_figure_general_form():
    _, _, result, truth = _run("reversing")
    assert result.form.kind == "general"
    fig = convergence_figures.build_estimates_figure(result, truth)
    assert len(fig.visible) == 16
    assert fig.panels[7].y.label == "rad/s²"
    assert fig.panels[15].title == "θ̂₂₈"


def test_residuals_figure(built, run):
    fig = built["residuals"]
    ax_t, ax_h = fig.panels
    assert "rad/s)" in ax_t.y.label
    assert ax_t.x.label == "time (s)"
    assert ax_h.x.label == "recorded samples (count)"
    assert fig.sharey
    legend = _below(fig)
    assert legend[0].startswith("right wheel, RMS")
    assert legend[1].startswith("left wheel, RMS")
    # the first steps' transient is far above the rest: the axis zooms and says how many samples it left out
    assert "beyond the axis" in legend[2]
    assert "10⁻⁶ rad/s" in ax_t.y.label  # the bulk is ~1e-6 rad/s on this noise-free log
    lo, hi = ax_t.y.lim
    assert 1e-6 * (hi - lo) < 0.5 * np.ptp(run.result.history.e)
    steps = [a for a in ax_h.artists if isinstance(a, Line)]
    assert len(steps) == 2  # one step histogram per wheel
    e = run.result.history.e / 1e-6
    for step, col in zip(steps, e.T, strict=True):  # counts of the samples within the axis
        assert step.x[1::2].sum() == np.count_nonzero((col >= lo) & (col <= hi))
    drawn = svgutil.panels(_svg(fig))
    assert svgutil.tick_labels(drawn[0], "y")
    assert not svgutil.tick_labels(drawn[1], "y")  # one error axis, labelled once


def test_excitation_figure(built, run):
    ax = built["excitation"].panels[0]
    assert ax.y.scale == "log"
    assert ax.y.label.endswith("(mixed units)")
    assert ax.x.label == "time (s)"
    lines = _labelled(ax)
    assert any("from t =" in label for label in lines)
    alpha = next(a for label, a in lines.items() if label.startswith("α ="))
    assert alpha.value == run.result.observer_settings.alpha
    labels = svgutil.tick_labels(svgutil.panels(_svg(built["excitation"]))[0], "y")
    assert "10⁻¹⁰" in labels  # alpha's decade, labelled in superscript
    assert all(re.fullmatch("10[⁻⁰¹²³⁴⁵⁶⁷⁸⁹]+", label) for label in labels)


def test_figures_never_import_matplotlib():
    code = (
        "import sys, numpy as np\n"
        "from types import SimpleNamespace\n"
        "import wmrid.reporting.figures as f, wmrid.reporting.fit_figures as ff, wmrid.fleets.figures\n"
        "log = SimpleNamespace(t=np.arange(5.0), eta=np.ones((5, 2)), tau=np.ones((5, 2)), source='x')\n"
        "assert f.log_overview(log).startswith(b'<?xml')\n"
        "assert ff.correlation_figure(['a', 'b'], np.eye(2)).startswith(b'<?xml')\n"
        "assert not [m for m in sys.modules if m.split('.')[0] in ('matplotlib', 'PIL')]\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr


def test_estimate_panels_zoom_past_early_excursions():
    t = np.linspace(0.0, 10.0, 1001)
    est = np.full_like(t, 0.79)
    est[:50] = np.linspace(8.0, 0.79, 50)  # the first half second far off, as at the box bound
    lo, hi = convergence_figures._settled_limits(t, est, np.array([0.92, 0.787]))
    assert lo < 0.787 < 0.92 < hi < 1.0
    assert convergence_figures._settled_limits(t, np.linspace(0.92, 0.79, 1001), np.array([0.92, 0.787])) is None


# --------------------------------------------------------------------------------------------------
# Titles, SVG text


def test_no_figure_title_and_no_source_in_titles(run):
    source = "/data/robots/run_0042_outdoor.mcap"
    result = dataclasses.replace(run.result, source=source)
    log = SimpleNamespace(t=run.log.t, eta=run.log.eta, tau=run.log.tau, source=source, notes=())
    every = _all_figures(SimpleNamespace(sim=run.sim, log=log, result=result, truth=run.truth))
    for name, fig in every.items():
        root = _svg(fig)
        assert not root.findall(f"{svgutil.NS}text"), name  # every text belongs to a panel or a legend
        for ax in fig.visible:
            assert "run_0042" not in ax.title, (name, ax.title)
            assert len(ax.title) <= 50, (name, ax.title)  # short panel titles
        assert "run_0042" not in " ".join(svgutil.texts(root))
    assert [ax.title for ax in every["residuals"].panels] == ["over time", "distribution"]
    assert every["excitation"].panels[0].title == "smallest eigenvalue of the information matrix Γ"
    assert every["path"].panels[0].title == ""
    assert every["estimates"].panels[0].title == "θ̂₁₁"
    # the rows' meaning, once in a figure-level title, is in the legend
    assert _below(every["estimates"])[-1] == "row i: wheel i (1 = right, 2 = left)"


def test_default_figures_are_page_wide():
    assert figures.FIGSIZE == (11.0, 4.2)
    log = SimpleNamespace(t=np.arange(5.0), eta=np.ones((5, 2)), tau=np.ones((5, 2)), source="x")
    w, h = figures.build_log_overview(log).size
    assert w == 11.0 * 96
    assert h > figures.FIGSIZE[1] * 96  # two stacked panels get more height


@pytest.mark.parametrize("name", ["log_overview", "convergence", "speed_fit", "correlation", "estimates", "path"])
def test_svg_keeps_text_as_text_and_is_deterministic(run, built, name):
    fig = built[name]
    svg = figures.render(fig, "svg")
    assert svg.count(b"<text") >= 5
    assert figures.render(fig, "svg") == svg  # the same bytes every time
    assert figures.render(_all_figures(run)[name]) == svg  # and from the same data built again
    labels = [ax.y.label for ax in fig.visible if ax.y.label]
    assert labels
    for label in labels:  # the labels are in the file as text, searchable
        assert label.replace("&", "&amp;").encode() in svg


# --------------------------------------------------------------------------------------------------
# Base parameters over time


def _display_scale(label: str) -> float:
    """The 10^n a panel's values were divided by (its y label says "10ⁿ unit", in superscript digits), else 1."""
    found = re.search("10([⁻⁰¹²³⁴⁵⁶⁷⁸⁹]+) ", label)
    digits = str.maketrans("⁻⁰¹²³⁴⁵⁶⁷⁸⁹", "-0123456789")
    return 10.0 ** int(found.group(1).translate(digits)) if found else 1.0


def test_base_convergence_figure(built, run):
    """Each panel in units of its std from the final estimate: the final estimate at 0, its band from -2 to 2, the
    truth at (true - final) / std; the title gives the final value, std and unit; labels at a readable size."""
    fig = built["convergence"]
    result = run.result
    names = result.form.base_names
    assert len(fig.visible) == len(names) == 8
    recovered = np.array([direct_recovery(th, result.form) for th in result.history.theta])
    t = result.history.t
    late = t >= t[-1] - 0.7 * (t[-1] - t[0])
    drawn = limits(fig.visible, True)
    for j, (ax, (_, ylim), name) in enumerate(zip(fig.visible, drawn, names, strict=True)):
        value, std = result.parameters[name]
        assert ax.title.split()[0] == name
        assert ax.title.endswith(f"\n{value:.6g} ± {std:.2g} {result.units[name]}")
        assert ax.y.label == "(estimate − final) / σ"
        lines = _labelled(ax)
        assert set(lines) == {"estimate (closed form)", "final ± 2σ", "final estimate", "true value"}
        assert lines["final estimate"].value == 0.0
        assert (lines["final ± 2σ"].lo, lines["final ± 2σ"].hi) == (-2.0, 2.0)
        true_z = (run.truth[name] - value) / std
        assert lines["true value"].value == pytest.approx(true_z, rel=1e-9)
        assert lines["true value"].dash == ":"
        est = lines["estimate (closed form)"]
        z = (recovered[:, j] - value) / std
        assert est.x[-1] == t[-1]
        assert est.y[-1] == pytest.approx(z[-1], rel=1e-9, abs=1e-9)
        # the axis shows the band, the truth and the settled trajectory ...
        y0, y1 = ylim
        shown = np.concatenate([[-2.0, 2.0, true_z], z[late]])
        assert y0 <= shown.min()
        assert shown.max() <= y1
        # ... and says "zoomed" exactly when some of the early transient is off it
        clipped = bool(np.any((z < y0) | (z > y1)))
        assert ("(zoomed)" in ax.title) == clipped
        assert ax.y.label_size >= 12
        assert ax.y.size >= 12  # tick labels
    # the start (~0.92, 17 % off) is far outside m11's panel: that one is zoomed
    assert "(zoomed)" in fig.panels[0].title
    assert [ax.x.label for ax in fig.panels[4:]] == ["time (s)"] * 4
    assert _below(fig) == ["estimate (closed form)", "final ± 2σ", "final estimate", "true value"]
    root = _svg(fig)
    assert svgutil.legend_texts(root) == _below(fig)
    for panel in svgutil.panels(root):  # the band, pale red, behind the estimate
        assert any(r.get("fill-opacity") == "0.18" for r in svgutil.data(panel).findall(f"{svgutil.NS}rect"))


def test_base_convergence_figure_without_history_truth_or_std(run):
    assert convergence_figures.build_base_convergence_figure(dataclasses.replace(run.result, observer=None)) is None
    assert convergence_figures.base_convergence_figure(dataclasses.replace(run.result, observer=None)) is None
    params = dict(run.result.parameters)
    for name, std in (("m11", math.nan), ("m12", None), ("m22", math.inf)):
        params[name] = (params[name][0], std)
    fig = convergence_figures.build_base_convergence_figure(dataclasses.replace(run.result, parameters=params))
    for ax in fig.visible:
        labels = set(_labelled(ax))
        name = ax.title.split()[0]
        has_band = "final ± 2σ" in labels
        assert labels - {"final ± 2σ"} == {"estimate (closed form)", "final estimate"}  # no truth given
        assert has_band == (name not in ("m11", "m12", "m22"))
        assert ax.y.label == ("estimate − final, %" if name in ("m11", "m12", "m22") else "(estimate − final) / σ")


def _synthetic_result(form, transient=True, n=400):
    """A result-like object whose history converges exponentially to a known theta0 (fast, no identification)."""
    names = form.base_names
    theta0 = np.array(
        [0.79, 0.24, 0.74, 0.21, 0.01, 0.015, 0.045, 0.04] + [0.3 + 0.1 * k for k in range(len(names) - 8)]
    )
    t = np.linspace(0.0, 10.0, n)
    offset = 0.5 * np.exp(-3.0 * t) if transient else np.zeros(n)
    theta = np.array([intermediate_parameters(theta0 * (1.0 + o), form) for o in offset])
    params = {name: (float(v), 1e-3 * float(v)) for name, v in zip(names, theta0, strict=True)}
    return SimpleNamespace(
        history=SimpleNamespace(t=t, theta=theta), form=form, parameters=params, units=dict(THETA0_UNITS)
    ), theta0


@pytest.mark.parametrize(
    ("form", "n_names"),
    [
        (RegressorForm("general", caster=True), 10),
        (RegressorForm("general", caster=True, geometry=(0.1, 0.2, -0.3, 0.0)), 9),
    ],
)
def test_base_convergence_figure_with_caster_drag(form, n_names):
    result, theta0 = _synthetic_result(form)
    names = form.base_names
    assert len(names) == n_names
    fig = convergence_figures.build_base_convergence_figure(result, dict(zip(names, theta0, strict=True)))
    assert len(fig.visible) == n_names  # 2 rows of 5, the unused panel left out
    assert {ax.cell[0] for ax in fig.visible} == {0, 1}
    assert {ax.cell[1] for ax in fig.visible} == set(range(5))
    assert [ax.title.split()[0] for ax in fig.visible] == list(names)
    assert fig.visible[-1].title.endswith({"Cw": " N m", "D1": " N"}[names[-1]])  # caster drag
    drawn = svgutil.panels(_svg(fig))
    for ax, panel in zip(fig.visible, drawn, strict=True):  # the bottom of each column shows the time axis
        below = any(o.cell[1] == ax.cell[1] and o.cell[0] > ax.cell[0] for o in fig.visible)
        assert (ax.x.label == "time (s)") == (not below), ax.title
        assert bool(svgutil.tick_labels(panel, "x")) == (not below), ax.title
    # the synthetic estimate starts 50 % off: every panel is zoomed on the band and the settled estimate
    assert all("(zoomed)" in ax.title for ax in fig.visible)
    quiet, _ = _synthetic_result(form, transient=False)
    fig = convergence_figures.build_base_convergence_figure(quiet)
    assert not any("(zoomed)" in ax.title for ax in fig.visible)
    for ax, (_, (lo, hi)), value in zip(fig.visible, limits(fig.visible, True), theta0, strict=True):
        scale = _display_scale(ax.y.label)
        assert lo * scale < value * (1 - 2e-3)
        assert value * (1 + 2e-3) < hi * scale


def test_zoom_limits():
    t = np.linspace(0.0, 10.0, 1001)
    est = np.full_like(t, 1.0)
    est[:50] = np.linspace(10.0, 1.0, 50)
    lo, hi, clipped = convergence_figures._zoom_limits(t, est, np.array([0.9, 1.1]))
    assert clipped
    assert lo == pytest.approx(0.88)
    assert hi == pytest.approx(1.12)
    lo, hi, clipped = convergence_figures._zoom_limits(t, np.linspace(1.2, 1.0, 1001), np.array([0.9, 1.1]))
    assert not clipped
    assert lo < 0.9
    assert hi > 1.2
    assert convergence_figures._zoom_limits(t, np.full_like(t, np.nan), np.array([np.nan])) is None


def test_zoom_limits_ignore_a_few_late_spikes():
    """A settled estimate with 5 spikes in its last 70 % (a recovery dividing by a near-zero m on a real log): the
    axis is set by the 1st-99th percentile of the settled part and the marks, the spikes are clipped."""
    t = np.linspace(0.0, 10.0, 1001)
    est = np.full_like(t, 1.0)
    est[[500, 520, 600, 700, 800]] = [3e4, -2e4, 5e3, -7e3, 1e4]
    lo, hi, clipped = convergence_figures._zoom_limits(t, est, np.array([0.9, 1.1]))
    assert clipped
    assert lo == pytest.approx(0.88)
    assert hi == pytest.approx(1.12)


# --------------------------------------------------------------------------------------------------
# Measured and predicted speeds


def test_speed_fit_figure():
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 2.0, 50)
    eta, eta_hat = rng.standard_normal((50, 2)), rng.standard_normal((50, 2))
    fig = fit_figures.build_speed_fit_figure(t, eta, eta_hat, [97.123, math.nan])
    top, bottom = fig.panels
    assert top.title == "right wheel: fit 97.1 %"
    assert bottom.title == "left wheel: fit —"
    assert bottom.x.label == "time (s)"
    assert top.y.label == bottom.y.label == "speed (rad/s)"
    assert fig.sharex
    for j, (ax, colour) in enumerate(((top, "C0"), (bottom, "C1"))):
        measured, model = (a for a in ax.artists if isinstance(a, Line))
        wheel = ("right", "left")[j]
        assert (measured.label, model.label) == (f"measured, {wheel} wheel", "model")
        np.testing.assert_array_equal(measured.x, t)
        np.testing.assert_array_equal(measured.y, eta[:, j])
        np.testing.assert_array_equal(model.x, t)
        np.testing.assert_array_equal(model.y, eta_hat[:, j])
        assert (measured.color, model.color, model.dash) == (colour, "k", "--")
        assert ax.y.size >= 12
    assert _below(fig) == ["measured, right wheel", "measured, left wheel", "model"]
    root = _svg(fig)
    for panel, colour in zip(svgutil.panels(root), ("#1f77b4", "#ff7f0e"), strict=True):
        lines = svgutil.polylines(svgutil.data(panel))
        assert [(p.get("stroke"), p.get("stroke-dasharray") is not None) for p in lines] == [
            (colour, False), ("#000000", True)
        ]  # fmt: skip
    fits = ([100, 0], [5.2345, 0])
    titles = [fit_figures.build_speed_fit_figure(t, eta, eta_hat, f).panels[0].title for f in fits]
    assert titles == ["right wheel: fit 100 %", "right wheel: fit 5.23 %"]
    assert fit_figures.build_speed_fit_figure(t, eta, eta_hat, None).panels[1].title == "left wheel: fit —"
    assert fit_figures.build_speed_fit_figure(t, eta, None, [1, 2]) is None
    assert fit_figures.speed_fit_figure(t, eta, None, [1, 2]) is None
    with pytest.raises(UsageError):
        fit_figures.build_speed_fit_figure(t, eta, eta_hat[:10], [1, 2])


def test_speed_fit_figure_decimates_long_logs(built, run):
    measured = built["speed_fit"].panels[0].artists[0]
    assert len(run.log.t) > MAX_POINTS >= len(measured.x)
    assert measured.y.max() == run.log.eta[:, 0].max()  # the extremes survive


# --------------------------------------------------------------------------------------------------
# Correlations


def _cell_text(value: float) -> str:
    text = f"{value:.2f}"
    return "0.00" if text == "-0.00" else text


def _cells(fig):
    """The cells' colours (k, k) as drawn: the rects of the heat map, row by row."""
    (panel, _) = svgutil.panels(_svg(fig))
    rects = [r.get("fill") for r in svgutil.data(panel).iter(f"{svgutil.NS}rect")]
    k = round(len(rects) ** 0.5)
    return np.array(rects).reshape(k, k)


def test_correlation_figure(run):
    names = list(run.result.form.base_names)
    cov = np.array(run.result.theta0_cov, dtype=object)
    cov[2, 5] = cov[5, 2] = None  # undefined covariances
    cov[0, 7] = cov[7, 0] = math.nan
    fig = fit_figures.build_correlation_figure(names, cov.tolist())
    ax, bar = fig.panels
    c = np.array(run.result.theta0_cov, dtype=float)
    expected = c / np.sqrt(np.outer(np.diag(c), np.diag(c)))  # computed here, independently
    texts = [a for a in ax.artists if isinstance(a, Text)]
    assert len(texts) == len(names) ** 2
    undefined = {(2, 5), (5, 2), (0, 7), (7, 0)}
    for text in texts:
        i, j = round(text.y), round(text.x)
        shown = text.text.replace("−", "-")
        if (i, j) in undefined:
            assert shown == "—"
        else:
            assert shown == _cell_text(expected[i, j]), (i, j)
            dark = abs(expected[i, j]) > 0.8
            light = abs(expected[i, j]) < 0.2
            if dark or light:
                assert text.color == ("white" if dark else "black"), (i, j)
    assert any(t.text == "1.00" for t in texts)
    assert ax.x.ticks == ax.y.ticks == (list(range(len(names))), names)
    assert ax.box[2] == ax.box[3]  # square cells
    cells = _cells(fig)
    assert cells[2, 5] == cells[0, 7] == MISSING
    assert all(cells[i, i] == "#67001f" for i in range(len(names)))  # +1: the darkest red
    assert bar.y.label == "correlation"
    root = _svg(fig)
    assert "correlation" in svgutil.texts(root)
    assert set(names) <= set(svgutil.texts(root))
    assert ax.x.size >= 12


def test_correlation_figure_colours_and_edge_cases():
    fig = fit_figures.build_correlation_figure(["a", "b", "c"], [[1.0, -1.0, 0.0], [-1.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    cells = _cells(fig)
    assert (cells[0, 0], cells[0, 1], cells[0, 2]) == ("#67001f", "#053061", "#f7f7f7")  # +1, -1, 0
    texts = {(round(a.y), round(a.x)): a for a in fig.panels[0].artists if isinstance(a, Text)}
    assert (texts[0, 1].text, texts[0, 1].color) == ("−1.00", "white")
    assert (texts[0, 2].text, texts[0, 2].color) == ("0.00", "black")
    assert fit_figures.build_correlation_figure(["m11"], [[1.0]]) is None
    assert fit_figures.correlation_figure([], []) is None
    # a parameter whose variance is undefined or zero: its whole row and column are undefined
    cov = [[4.0, 1.0, None], [1.0, 1.0, 0.5], [None, 0.5, 0.0]]
    fig = fit_figures.build_correlation_figure(["a", "b", "c"], cov)
    cells = {(round(t.y), round(t.x)): t.text for t in fig.panels[0].artists if isinstance(t, Text)}
    assert cells[(0, 1)] == cells[(1, 0)] == "0.50"
    assert cells[(0, 0)] == cells[(1, 1)] == "1.00"
    assert all(cells[(2, j)] == cells[(j, 2)] == "—" for j in range(3))
    np.testing.assert_allclose(fit_figures.correlation_matrix([[4.0, -2.0], [-2.0, 4.0]]), [[1.0, -0.5], [-0.5, 1.0]])
    fig = fit_figures.build_correlation_figure(["a", "b"], [[1.0, -0.999], [-0.999, 1.0]])
    assert [t.text for t in fig.panels[0].artists if isinstance(t, Text)][1] == "−1.00"
    with pytest.raises(UsageError):
        fit_figures.build_correlation_figure(["a", "b", "c"], np.eye(2))
