"""Figures: valid SVG/PNG, labelled axes with units, no line above the point budget, decimation."""

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
from hypothesis import given, settings, strategies as st
from locations import ROOT_DIR
from matplotlib.colors import to_rgba

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
from wmrid.sim.simulate import simulate

ROOT = ROOT_DIR
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


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
# Figures


def test_line_data_within_point_budget(built):
    longest = 0
    for name, fig in built.items():
        for ax in fig.axes:
            for line in ax.get_lines():
                n = len(line.get_xdata())
                assert n <= MAX_POINTS, f"{name}: {line.get_label()!r} has {n} points"
                assert len(line.get_ydata()) == n
                longest = max(longest, n)
    assert longest > MAX_POINTS // 2  # the logs (10001 samples) were long enough to need decimating


BOTH = ("svg", "png")


@pytest.mark.parametrize(
    ("name", "formats", "render"),
    [
        ("log_overview", BOTH, lambda run, fmt: figures.log_overview(run.log, fmt=fmt)),
        ("path", BOTH, lambda run, fmt: figures.path_figure(run.sim.pose, fmt=fmt)),
        # estimates_figure in both formats, split between its two modes (14 panels take ~1 s per format)
        ("estimates", ("png",), lambda run, fmt: convergence_figures.estimates_figure(run.result, run.truth, fmt=fmt)),
        (
            "errors",
            ("svg",),
            lambda run, fmt: convergence_figures.estimates_figure(run.result, run.truth, error_mode=True, fmt=fmt),
        ),
        ("residuals", BOTH, lambda run, fmt: fit_figures.residuals_figure(run.result, fmt=fmt)),
        ("excitation", BOTH, lambda run, fmt: fit_figures.excitation_figure(run.result, fmt=fmt)),
        pytest.param(
            "convergence",
            BOTH,
            lambda run, fmt: convergence_figures.base_convergence_figure(run.result, run.truth, fmt=fmt),
            marks=pytest.mark.slow(reason="3 s; drawn as SVG by the determinism test, as PNG by test_terminal's .md"),
        ),
        (
            "speed_fit",
            BOTH,
            lambda run, fmt: fit_figures.speed_fit_figure(
                run.log.t, run.log.eta, _model_speeds(run.log), [97.1, 95], fmt
            ),
        ),
        (
            "correlation",
            BOTH,
            lambda run, fmt: fit_figures.correlation_figure(run.result.form.base_names, run.result.theta0_cov, fmt),
        ),
    ],
)
def test_renders_svg_and_png(run, name, formats, render):
    if "svg" in formats:
        svg = render(run, "svg")
        assert svg.startswith(b"<?xml")
        assert b"<svg" in svg[:2000]
    if "png" in formats:
        png = render(run, "png")
        assert png.startswith(PNG_MAGIC)
        width, height = int.from_bytes(png[16:20], "big"), int.from_bytes(png[20:24], "big")
        assert 600 <= width <= 2400
        assert 400 <= height <= 1000


def test_render_default_is_svg_deterministic_and_rejects_other_formats(run, built):
    svg = figures.render(built["log_overview"])
    assert svg.startswith(b"<?xml")
    assert figures.render(figures.build_log_overview(run.log)) == svg  # no date, no random ids
    with pytest.raises(UsageError, match="svg, png"):
        figures.render(built["log_overview"], "pdf")


def test_log_overview_labels(built, run):
    fig = built["log_overview"]
    top, bottom = fig.axes
    assert top.get_ylabel() == "wheel torque (N m)"
    assert bottom.get_ylabel() == "wheel speed (rad/s)"
    assert bottom.get_xlabel().endswith("(s)")
    assert top.get_shared_x_axes().joined(top, bottom)
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["right wheel", "left wheel"]
    assert fig.get_suptitle() == ""  # the report's caption names the figure
    pwm = SimpleNamespace(t=run.log.t + 1.7e9, eta=run.log.eta, tau=run.log.tau, source="x", effort_unit="PWM")
    fig = figures.build_log_overview(pwm)
    assert fig.axes[0].get_ylabel() == "wheel effort (PWM)"
    assert fig.axes[1].get_xlim()[0] == 0.0  # epoch stamps drawn from the first sample


def test_path_figure(built, run):
    ax = built["path"].axes[0]
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("x (m)", "y (m)")
    assert ax.get_aspect() == 1.0
    labels = [line.get_label() for line in ax.get_lines()]
    assert labels == ["path", "start", "end"]
    start, end = ax.get_lines()[1:]
    assert (start.get_xdata()[0], start.get_ydata()[0]) == tuple(run.sim.pose[0, :2])
    assert (end.get_xdata()[0], end.get_ydata()[0]) == tuple(run.sim.pose[-1, :2])
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
    assert len(fig.axes) == 2 * p
    truth_theta = intermediate_parameters(np.array([run.truth[n] for n in THETA0_NAMES]), run.result.form)
    for n, ax in enumerate(fig.axes):
        i, k = divmod(n, p)
        assert _units_ok(ax.get_ylabel()), ax.get_ylabel()
        assert convergence_figures._subscript(f"{i + 1}{k + 1}") in ax.get_title()
        lines = {line.get_label(): line for line in ax.get_lines()}
        assert set(lines) == {"estimate", "start value", "true value"}
        assert lines["start value"].get_linestyle() == "--"
        assert lines["true value"].get_linestyle() == ":"
        ratio = lines["true value"].get_ydata()[0] / truth_theta[i, k]
        scale = 10.0 ** round(-np.log10(ratio))  # 1 unless the label says 10^n
        assert ratio * scale == pytest.approx(1.0)
        assert (scale == 1.0) == (_display_scale(ax.get_ylabel()) == 1.0)
        assert lines["estimate"].get_ydata()[-1] * scale == pytest.approx(truth_theta[i, k], rel=1e-3, abs=1e-6)
    assert all(ax.get_xlabel() == "time (s)" for ax in fig.axes[p:])
    # the whole truth file is accepted as well as its "parameters" table
    whole = json.loads((ROOT / "sample_logs" / "paper_sinusoid.csv.truth.json").read_text())
    np.testing.assert_allclose(convergence_figures.true_theta(whole, run.result.form), truth_theta, rtol=1e-12)
    with pytest.raises(UsageError, match="Fd2"):
        convergence_figures.true_theta({"m11": 1.0}, run.result.form)
    no_truth = convergence_figures.build_estimates_figure(run.result)
    assert {line.get_label() for line in no_truth.axes[0].get_lines()} == {"estimate", "start value"}


def test_estimation_error_figure(built, run):
    fig = built["errors"]
    for ax in fig.axes:
        assert _units_ok(ax.get_ylabel())
        lines = {line.get_label(): line for line in ax.get_lines()}
        assert set(lines) == {"zero error", "error of estimate", "error of the start value"}
        err = lines["error of estimate"].get_ydata()
        start_err = lines["error of the start value"].get_ydata()[0]
        assert abs(err[-1]) < 1e-2 * max(abs(start_err), 1e-12) or abs(err[-1]) < 1e-6
    with pytest.raises(UsageError, match="truth"):
        convergence_figures.build_estimates_figure(run.result, error_mode=True)


def test_estimates_figure_general_form():
    _, _, result, truth = _run("reversing")
    assert result.form.kind == "general"
    fig = convergence_figures.build_estimates_figure(result, truth)
    assert len(fig.axes) == 16
    assert fig.axes[7].get_ylabel() == "rad/s²"
    assert fig.axes[15].get_title() == "θ̂₂₈"


def test_residuals_figure(built, run):
    ax_t, ax_h = built["residuals"].axes
    assert "rad/s)" in ax_t.get_ylabel()
    assert ax_t.get_xlabel() == "time (s)"
    assert ax_h.get_xlabel() == "recorded samples (count)"
    assert ax_t.get_shared_y_axes().joined(ax_t, ax_h)
    legend = [t.get_text() for t in ax_t.get_legend().get_texts()]
    assert legend[0].startswith("right wheel, RMS")
    assert legend[1].startswith("left wheel, RMS")
    # the first steps' transient is far above the rest: the axis zooms and says how many samples it left out
    assert "beyond the axis" in legend[2]
    assert "10⁻⁶ rad/s" in ax_t.get_ylabel()  # the bulk is ~1e-6 rad/s on this noise-free log
    lo, hi = ax_t.get_ylim()
    assert 1e-6 * (hi - lo) < 0.5 * np.ptp(run.result.history.e)
    assert len(ax_h.patches) == 2  # one step histogram per wheel


def test_excitation_figure(built, run):
    ax = built["excitation"].axes[0]
    assert ax.get_yscale() == "log"
    assert ax.get_ylabel().endswith("(mixed units)")
    assert ax.get_xlabel() == "time (s)"
    labels = [line.get_label() for line in ax.get_lines()]
    assert any("from t =" in label for label in labels)
    alpha_line = next(line for line in ax.get_lines() if line.get_label().startswith("α ="))
    assert alpha_line.get_ydata()[0] == run.result.observer_settings.alpha


def test_matplotlib_is_imported_lazily_and_pyplot_never():
    code = (
        "import sys, numpy as np\n"
        "from types import SimpleNamespace\n"
        "import wmrid.reporting.figures as f\n"
        "assert 'matplotlib' not in sys.modules\n"
        "log = SimpleNamespace(t=np.arange(5.0), eta=np.ones((5, 2)), tau=np.ones((5, 2)), source='x')\n"
        "assert f.log_overview(log, fmt='png').startswith(b'\\x89PNG')\n"
        "assert 'matplotlib.pyplot' not in sys.modules\n"
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


def _titles(fig):
    return [ax.get_title(loc=loc) for ax in fig.axes for loc in ("left", "center", "right")]


def test_no_figure_title_and_no_source_in_titles(run):
    source = "/data/robots/run_0042_outdoor.mcap"
    result = dataclasses.replace(run.result, source=source)
    log = SimpleNamespace(t=run.log.t, eta=run.log.eta, tau=run.log.tau, source=source, notes=())
    every = _all_figures(SimpleNamespace(sim=run.sim, log=log, result=result, truth=run.truth))
    for name, fig in every.items():
        assert fig.get_suptitle() == "", name
        assert not fig.texts, name  # no figure-level text standing in for a title
        for title in _titles(fig):
            assert "run_0042" not in title, (name, title)
            assert len(title) <= 50, (name, title)  # short panel titles
    assert _titles(every["residuals"])[1::3] == ["over time", "distribution"]
    assert every["excitation"].axes[0].get_title() == "smallest eigenvalue of the information matrix Γ"
    assert _titles(every["path"]) == ["", "", ""]
    assert every["estimates"].axes[0].get_title() == "θ̂₁₁"
    # the rows' meaning, once in a figure-level title, is in the legend
    legend = [t.get_text() for t in every["estimates"].legends[0].get_texts()]
    assert legend[-1] == "row i: wheel i (1 = right, 2 = left)"


def test_default_figures_are_page_wide():
    assert figures.FIGSIZE == (11.0, 4.2)
    log = SimpleNamespace(t=np.arange(5.0), eta=np.ones((5, 2)), tau=np.ones((5, 2)), source="x")
    w, h = figures.build_log_overview(log).get_size_inches()
    assert w == 11.0
    assert h > figures.FIGSIZE[1]  # two stacked panels get more height


@pytest.mark.parametrize("name", ["log_overview", "convergence", "speed_fit", "correlation"])
def test_svg_keeps_text_as_text_and_is_deterministic(built, name):
    fig = built[name]
    svg = figures.render(fig, "svg")
    assert svg.count(b"<text") >= 5
    assert b'<path id="DejaVuSans' not in svg  # no glyph outlines
    assert figures.render(fig, "png").startswith(PNG_MAGIC)
    assert figures.render(fig, "svg") == svg  # the same bytes every time, a PNG in between or not
    labels = [ax.get_ylabel() for ax in fig.axes if "$" not in ax.get_ylabel() and ax.get_ylabel()]
    assert labels
    for label in labels:  # the labels are in the file as text, searchable
        assert label.replace("&", "&amp;").encode() in svg


@pytest.mark.slow  # 2.7 s; the same figure rendered twice is checked in the default run
def test_svg_is_byte_identical_across_builds(run):
    one = figures.render(convergence_figures.build_base_convergence_figure(run.result, run.truth))
    two = figures.render(convergence_figures.build_base_convergence_figure(run.result, run.truth))
    assert one == two


# --------------------------------------------------------------------------------------------------
# Base parameters over time


def _display_scale(label: str) -> float:
    """The 10^n a panel's values were divided by (its y label says "10ⁿ unit", in superscript digits), else 1."""
    found = re.search("10([⁻⁰¹²³⁴⁵⁶⁷⁸⁹]+) ", label)
    digits = str.maketrans("⁻⁰¹²³⁴⁵⁶⁷⁸⁹", "-0123456789")
    return 10.0 ** int(found.group(1).translate(digits)) if found else 1.0


def _band(ax):
    (patch,) = [p for p in ax.patches if p.get_label() == "final ± 2σ"]
    y = patch.get_patch_transform().transform(patch.get_path().vertices)[:, 1]
    return float(y.min()), float(y.max())


def test_base_convergence_figure(built, run):
    """Each panel in units of its std from the final estimate: the final estimate at 0, its band from -2 to 2, the
    truth at (true - final) / std; the title gives the final value, std and unit; labels at a readable size."""
    fig = built["convergence"]
    result = run.result
    names = result.form.base_names
    assert len(fig.axes) == len(names) == 8
    recovered = np.array([direct_recovery(th, result.form) for th in result.history.theta])
    t = result.history.t
    late = t >= t[-1] - 0.7 * (t[-1] - t[0])
    for j, (ax, name) in enumerate(zip(fig.axes, names, strict=True)):
        value, std = result.parameters[name]
        assert ax.get_title().split()[0] == name
        assert ax.get_title().endswith(f"\n{value:.6g} ± {std:.2g} {result.units[name]}")
        assert ax.get_ylabel() == "(estimate − final) / σ"
        lines = {line.get_label(): line for line in ax.get_lines()}
        assert set(lines) == {"estimate (closed form)", "final estimate", "true value"}
        assert lines["final estimate"].get_ydata()[0] == 0.0
        assert _band(ax) == pytest.approx((-2.0, 2.0), abs=1e-12)
        true_z = (run.truth[name] - value) / std
        assert lines["true value"].get_ydata()[0] == pytest.approx(true_z, rel=1e-9)
        assert lines["true value"].get_linestyle() == ":"
        est = lines["estimate (closed form)"]
        z = (recovered[:, j] - value) / std
        assert est.get_xdata()[-1] == t[-1]
        assert est.get_ydata()[-1] == pytest.approx(z[-1], rel=1e-9, abs=1e-9)
        # the axis shows the band, the truth and the settled trajectory ...
        y0, y1 = ax.get_ylim()
        shown = np.concatenate([[-2.0, 2.0, true_z], z[late]])
        assert y0 <= shown.min()
        assert shown.max() <= y1
        # ... and says "zoomed" exactly when some of the early transient is off it
        clipped = bool(np.any((z < y0) | (z > y1)))
        assert ("(zoomed)" in ax.get_title()) == clipped
        assert ax.yaxis.get_label().get_fontsize() >= 10
        assert all(label.get_fontsize() >= 10 for label in ax.get_yticklabels())
    # the start (~0.92, 17 % off) is far outside m11's panel: that one is zoomed
    assert "(zoomed)" in fig.axes[0].get_title()
    assert [ax.get_xlabel() for ax in fig.axes[4:]] == ["time (s)"] * 4
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert legend == ["estimate (closed form)", "final ± 2σ", "final estimate", "true value"]


def test_base_convergence_figure_without_history_truth_or_std(run):
    assert convergence_figures.build_base_convergence_figure(dataclasses.replace(run.result, observer=None)) is None
    assert convergence_figures.base_convergence_figure(dataclasses.replace(run.result, observer=None)) is None
    params = dict(run.result.parameters)
    for name, std in (("m11", math.nan), ("m12", None), ("m22", math.inf)):
        params[name] = (params[name][0], std)
    fig = convergence_figures.build_base_convergence_figure(dataclasses.replace(run.result, parameters=params))
    for ax in fig.axes:
        labels = {line.get_label() for line in ax.get_lines()}
        assert labels == {"estimate (closed form)", "final estimate"}  # no truth given
        has_band = any(p.get_label() == "final ± 2σ" for p in ax.patches)
        name = ax.get_title().split()[0]
        assert has_band == (name not in ("m11", "m12", "m22"))
        assert ax.get_ylabel() == ("estimate − final, %" if name in ("m11", "m12", "m22") else "(estimate − final) / σ")


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
    assert len(fig.axes) == n_names  # 2 rows of 5, the unused panel removed
    assert {ax.get_subplotspec().get_geometry()[:2] for ax in fig.axes} == {(2, 5)}
    assert [ax.get_title().split()[0] for ax in fig.axes] == list(names)
    assert fig.axes[-1].get_title().endswith({"Cw": " N m", "D1": " N"}[names[-1]])  # caster drag
    for ax, name in zip(fig.axes, names, strict=True):  # the bottom of each column shows the time axis
        below = any(
            other.get_subplotspec().rowspan.start == 1
            for other in fig.axes
            if other.get_subplotspec().colspan == ax.get_subplotspec().colspan and other is not ax
        )
        assert (ax.get_xlabel() == "time (s)") == (not below), name
    # the synthetic estimate starts 50 % off: every panel is zoomed on the band and the settled estimate
    assert all("(zoomed)" in ax.get_title() for ax in fig.axes)
    quiet, _ = _synthetic_result(form, transient=False)
    fig = convergence_figures.build_base_convergence_figure(quiet)
    assert not any("(zoomed)" in ax.get_title() for ax in fig.axes)
    for ax, value in zip(fig.axes, theta0, strict=True):
        lo, hi = ax.get_ylim()
        scale = _display_scale(ax.get_ylabel())
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
    top, bottom = fig.axes
    assert top.get_title() == "right wheel: fit 97.1 %"
    assert bottom.get_title() == "left wheel: fit —"
    assert bottom.get_xlabel() == "time (s)"
    assert top.get_ylabel() == bottom.get_ylabel() == "speed (rad/s)"
    assert top.get_shared_x_axes().joined(top, bottom)
    for j, (ax, colour) in enumerate(((top, "C0"), (bottom, "C1"))):
        measured, model = ax.get_lines()
        assert (measured.get_label(), model.get_label()) == ("measured", "model")
        np.testing.assert_array_equal(measured.get_xdata(), t)
        np.testing.assert_array_equal(measured.get_ydata(), eta[:, j])
        np.testing.assert_array_equal(model.get_xdata(), t)
        np.testing.assert_array_equal(model.get_ydata(), eta_hat[:, j])
        assert to_rgba(measured.get_color()) == to_rgba(colour)
        assert to_rgba(model.get_color()) == to_rgba("k")
        assert model.get_linestyle() == "--"
        assert [x.get_text() for x in ax.get_legend().get_texts()] == ["measured", "model"]
        assert all(label.get_fontsize() >= 10 for label in ax.get_yticklabels())
    fits = ([100, 0], [5.2345, 0])
    titles = [fit_figures.build_speed_fit_figure(t, eta, eta_hat, f).axes[0].get_title() for f in fits]
    assert titles == ["right wheel: fit 100 %", "right wheel: fit 5.23 %"]
    assert fit_figures.build_speed_fit_figure(t, eta, eta_hat, None).axes[1].get_title() == "left wheel: fit —"
    assert fit_figures.build_speed_fit_figure(t, eta, None, [1, 2]) is None
    assert fit_figures.speed_fit_figure(t, eta, None, [1, 2]) is None
    with pytest.raises(UsageError):
        fit_figures.build_speed_fit_figure(t, eta, eta_hat[:10], [1, 2])


def test_speed_fit_figure_decimates_long_logs(built, run):
    ax = built["speed_fit"].axes[0]
    measured = ax.get_lines()[0]
    assert len(run.log.t) > MAX_POINTS >= len(measured.get_xdata())
    assert measured.get_ydata().max() == run.log.eta[:, 0].max()  # the extremes survive


# --------------------------------------------------------------------------------------------------
# Correlations


def _cell_text(value: float) -> str:
    text = f"{value:.2f}"
    return "0.00" if text == "-0.00" else text


def test_correlation_figure(run):
    names = list(run.result.form.base_names)
    cov = np.array(run.result.theta0_cov, dtype=object)
    cov[2, 5] = cov[5, 2] = None  # undefined covariances
    cov[0, 7] = cov[7, 0] = math.nan
    fig = fit_figures.build_correlation_figure(names, cov.tolist())
    ax, bar = fig.axes
    c = np.array(run.result.theta0_cov, dtype=float)
    expected = c / np.sqrt(np.outer(np.diag(c), np.diag(c)))  # computed here, independently
    assert len(ax.texts) == len(names) ** 2
    undefined = {(2, 5), (5, 2), (0, 7), (7, 0)}
    for text in ax.texts:
        j, i = (round(v) for v in text.get_position())
        shown = text.get_text().replace("−", "-")
        if (i, j) in undefined:
            assert shown == "—"
        else:
            assert shown == _cell_text(expected[i, j]), (i, j)
            dark = abs(expected[i, j]) > 0.8
            light = abs(expected[i, j]) < 0.2
            if dark or light:
                assert to_rgba(text.get_color()) == to_rgba("white" if dark else "black"), (i, j)
    assert any(t.get_text() == "1.00" for t in ax.texts)
    assert [t.get_text() for t in ax.get_xticklabels()] == names
    assert [t.get_text() for t in ax.get_yticklabels()] == names
    mesh = ax.collections[0]
    assert mesh.get_cmap().name.startswith("RdBu_r")
    assert (mesh.norm.vmin, mesh.norm.vmax) == (-1.0, 1.0)
    assert mesh.get_cmap().get_bad() == pytest.approx(to_rgba("0.75"))
    assert np.ma.getmaskarray(mesh.get_array()).reshape(len(names), -1)[2, 5]
    assert bar.get_ylabel() == "correlation"
    assert all(label.get_fontsize() >= 10 for label in ax.get_xticklabels())


def test_correlation_figure_edge_cases():
    assert fit_figures.build_correlation_figure(["m11"], [[1.0]]) is None
    assert fit_figures.correlation_figure([], []) is None
    # a parameter whose variance is undefined or zero: its whole row and column are undefined
    cov = [[4.0, 1.0, None], [1.0, 1.0, 0.5], [None, 0.5, 0.0]]
    fig = fit_figures.build_correlation_figure(["a", "b", "c"], cov)
    cells = {tuple(round(v) for v in t.get_position())[::-1]: t.get_text() for t in fig.axes[0].texts}
    assert cells[(0, 1)] == cells[(1, 0)] == "0.50"
    assert cells[(0, 0)] == cells[(1, 1)] == "1.00"
    assert all(cells[(2, j)] == cells[(j, 2)] == "—" for j in range(3))
    np.testing.assert_allclose(fit_figures.correlation_matrix([[4.0, -2.0], [-2.0, 4.0]]), [[1.0, -0.5], [-0.5, 1.0]])
    assert (
        fit_figures.build_correlation_figure(["a", "b"], [[1.0, -0.999], [-0.999, 1.0]]).axes[0].texts[1].get_text()
        == "−1.00"
    )
    with pytest.raises(UsageError):
        fit_figures.build_correlation_figure(["a", "b", "c"], np.eye(2))
