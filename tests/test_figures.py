"""Figures: valid SVG/PNG, labelled axes with units, no line above the point budget, decimation."""

from __future__ import annotations

import itertools
import json
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wmrid.core.errors import UsageError
from wmrid.estimators.identify import identify
from wmrid.model.dynamics import THETA0_NAMES, base_parameters, intermediate_parameters, named_base
from wmrid.model.robot import BUILTIN_ROBOTS
from wmrid.reporting import figures
from wmrid.reporting.figures import MAX_POINTS, decimate_for_display
from wmrid.sim.simulate import simulate

ROOT = Path(__file__).resolve().parents[1]
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


def _all_figures(run):
    return {
        "log_overview": figures.build_log_overview(run.log),
        "path": figures.build_path_figure(run.sim.pose),
        "estimates": figures.build_estimates_figure(run.result, run.truth),
        "errors": figures.build_estimates_figure(run.result, run.truth, error_mode=True),
        "residuals": figures.build_residuals_figure(run.result),
        "excitation": figures.build_excitation_figure(run.result),
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
        edges = figures._bin_edges(len(t), max_points)
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
        ("estimates", ("png",), lambda run, fmt: figures.estimates_figure(run.result, run.truth, fmt=fmt)),
        (
            "errors",
            ("svg",),
            lambda run, fmt: figures.estimates_figure(run.result, run.truth, error_mode=True, fmt=fmt),
        ),
        ("residuals", BOTH, lambda run, fmt: figures.residuals_figure(run.result, fmt=fmt)),
        ("excitation", BOTH, lambda run, fmt: figures.excitation_figure(run.result, fmt=fmt)),
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
    assert fig.get_suptitle()
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
        assert f"_{{{i + 1}{k + 1}}}" in ax.get_title()
        lines = {line.get_label(): line for line in ax.get_lines()}
        assert set(lines) == {"estimate", "start value", "true value"}
        assert lines["start value"].get_linestyle() == "--"
        assert lines["true value"].get_linestyle() == ":"
        ratio = lines["true value"].get_ydata()[0] / truth_theta[i, k]
        scale = 10.0 ** round(-np.log10(ratio))  # 1 unless the label says 10^n
        assert ratio * scale == pytest.approx(1.0)
        assert (scale == 1.0) == ("10^" not in ax.get_ylabel())
        assert lines["estimate"].get_ydata()[-1] * scale == pytest.approx(truth_theta[i, k], rel=1e-3, abs=1e-6)
    assert all(ax.get_xlabel() == "time (s)" for ax in fig.axes[p:])
    # the whole truth file is accepted as well as its "parameters" table
    whole = json.loads((ROOT / "sample_logs" / "paper_sinusoid.csv.truth.json").read_text())
    np.testing.assert_allclose(figures.true_theta(whole, run.result.form), truth_theta, rtol=1e-12)
    with pytest.raises(UsageError, match="Fd2"):
        figures.true_theta({"m11": 1.0}, run.result.form)
    no_truth = figures.build_estimates_figure(run.result)
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
        figures.build_estimates_figure(run.result, error_mode=True)


def test_estimates_figure_general_form():
    _, _, result, truth = _run("reversing")
    assert result.form.kind == "general"
    fig = figures.build_estimates_figure(result, truth)
    assert len(fig.axes) == 16
    assert fig.axes[7].get_ylabel() == "rad/s²"
    assert fig.axes[15].get_title() == r"$\hat\theta_{28}$"


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
    assert "$10^{-6}$ rad/s" in ax_t.get_ylabel()  # the bulk is ~1e-6 rad/s on this noise-free log
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
    assert alpha_line.get_ydata()[0] == run.result.settings.alpha


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
    lo, hi = figures._settled_limits(t, est, np.array([0.92, 0.787]))
    assert lo < 0.787 < 0.92 < hi < 1.0
    assert figures._settled_limits(t, np.linspace(0.92, 0.79, 1001), np.array([0.92, 0.787])) is None
