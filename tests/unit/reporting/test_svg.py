"""wmrid's SVG layer (wmrid.reporting.svg): well-formed, escaped, deterministic documents; lines broken by NaN,
reduced for display and simplified within 0.1 px; legends, shared axes, equal aspect, log and date axes, colours."""

from __future__ import annotations

import datetime as dt
import itertools
import math
import re

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from svgutil import NS, data, frame, legend_texts, panels, parse, points, polylines, texts, tick_labels

from wmrid.reporting.decimate import MAX_POINTS
from wmrid.reporting.svg import PX_PER_INCH, Figure
from wmrid.reporting.svg_artists import simplify
from wmrid.reporting.svg_axes import date_number, text_width
from wmrid.reporting.svg_draw import limits
from wmrid.reporting.svg_style import (
    CLIP_MARGIN,
    MISSING,
    RDBU_R,
    TAB10,
    clip_line,
    clip_polygon,
    colour,
    diverging,
    escape,
    luminance,
    num,
)


def _one(**kwargs):
    fig = Figure((6.0, 3.0), **kwargs)
    return fig, fig.panels[0]


def test_a_document_with_its_size_and_text_as_text():
    fig, ax = _one()
    ax.line([0, 1, 2], [0, 1, 0], label="a line")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("speed (rad/s)")
    ax.set_title("a title")
    svg = fig.to_svg()
    assert svg.startswith(b'<?xml version="1.0" encoding="utf-8"?>\n<svg xmlns="http://www.w3.org/2000/svg"')
    root = parse(svg)
    assert (root.get("width"), root.get("height"), root.get("viewBox")) == ("576", "288", "0 0 576 288")
    assert root.get("font-family") == "sans-serif"
    assert {"time (s)", "speed (rad/s)", "a title"} <= set(texts(root))
    assert len(panels(root)) == 1
    assert b"<path id=" not in svg  # no glyph outlines


def test_special_characters_are_escaped():
    fig, ax = _one()
    name = 'R<1> & "co" \x07'
    ax.line([0, 1], [0, 1], label=name)
    ax.legend("upper left")
    ax.set_title(name)
    ax.x.ticks = ([0.0, 1.0], [name, "<b>"])
    svg = fig.to_svg()
    root = parse(svg)  # well-formed
    assert texts(root).count('R<1> & "co" ') == 3  # title, legend, tick label; the control character dropped
    assert "<b>" in texts(root)
    assert b"R&lt;1&gt; &amp; &quot;co&quot;" in svg
    assert escape("a<b&c") == "a&lt;b&amp;c"


def test_characters_xml_forbids_are_dropped_everywhere_text_goes():
    """U+FFFE, U+FFFF, lone surrogates (which UTF-8 cannot encode either) and controls, in a title, a legend and a
    tick label: the document encodes and parses, the rest of the text kept."""
    fig, ax = _one()
    name = "nc\uffff\ufffe\ud800\udfff\x00\x1b\r<é>\U0001f600"
    ax.line([0, 1], [0, 1], label=name)
    ax.legend("upper left")
    ax.set_title(name)
    ax.x.ticks = ([0.0], [name])
    svg = fig.to_svg()  # no UnicodeEncodeError
    assert texts(parse(svg)).count("nc<é>\U0001f600") == 3  # well-formed: title, legend, tick label
    assert escape("a\ufffeb\udc80c\td\ne") == "abc\td\ne"


def test_cell_and_gradient_colours_are_checked():
    from wmrid.core.errors import UsageError

    for draw in (lambda ax: ax.cells([["#00ff00", '"/><script/>']]), lambda ax: ax.gradient([(0.0, 'red"')])):
        fig, ax = _one()
        draw(ax)
        with pytest.raises(UsageError, match="colour"):
            fig.to_svg()
    fig, ax = _one()
    ax.cells([["C3", "0.5"]])
    ax.gradient([(0.0, "#053061"), (1.0, "C1")])
    root = parse(fig.to_svg())
    fills = [r.get("fill") for r in data(panels(root)[0]).iter(f"{NS}rect")]
    assert {TAB10[3], "#808080"} <= set(fills)
    assert [s.get("stop-color") for s in root.iter(f"{NS}stop")] == ["#053061", TAB10[1]]


def test_same_figure_same_bytes_and_ids_unique_across_figures():
    def build(shift):
        fig, ax = _one()
        ax.line(np.arange(50.0), np.sin(np.arange(50.0)) + shift)
        return fig

    one, two, other = build(0.0).to_svg(), build(0.0).to_svg(), build(1.0).to_svg()
    assert one == two  # no date, no random id
    ids = set(re.findall(rb'id="([^"]+)"', one))
    assert ids
    assert ids.isdisjoint(re.findall(rb'id="([^"]+)"', other))  # two figures in one page never share an id
    for ref in re.findall(rb"url\(#([^)]+)\)", one):
        assert ref in ids


def test_nan_breaks_a_line_and_a_lone_point_is_not_drawn():
    fig, ax = _one()
    y = np.array([0.0, 1.0, 0.0, np.nan, 3.0, 2.0, np.nan, 5.0, np.nan, 1.0, 2.0])
    ax.line(np.arange(len(y)), y)
    lines = polylines(data(panels(parse(fig.to_svg()))[0]))
    assert [len(points(p)) for p in lines] == [3, 2, 2]  # the lone 5.0 has no neighbour to join


def test_a_long_line_is_reduced_for_display_its_extremes_kept():
    fig, ax = _one()
    t = np.arange(200_000) * 1e-3
    y = np.sin(t) + 0.01 * np.random.default_rng(1).standard_normal(len(t))
    y[123_456] = 40.0
    line = ax.line(t, y)
    assert len(line.x) <= min(MAX_POINTS, 4 * ax.box[2])  # 4 points per px of the panel's width
    assert line.y.max() == 40.0
    (drawn,) = polylines(data(panels(parse(fig.to_svg()))[0]))
    assert len(points(drawn)) <= MAX_POINTS
    _, top, _, _ = frame(panels(parse(fig.to_svg()))[0])
    assert points(drawn)[:, 1].min() == pytest.approx(top + 0.05 * (ax.box[3] / 1.1), abs=0.6)  # the spike drawn
    wide = Figure((40.0, 3.0)).panels[0].line(t, y)
    assert len(wide.x) <= MAX_POINTS  # however wide the panel
    assert len(Figure((6.0, 3.0)).panels[0].line(t, y, decimate=False).x) <= MAX_POINTS


def test_simplify_keeps_the_drawing_within_a_tenth_of_a_pixel():
    x = np.linspace(0.0, 500.0, 2001)
    straight = simplify(x, 2 * x + 1)
    assert straight.tolist() == [0, 2000]
    y = 100 + 80 * np.sin(x / 40)
    y[700] += 30  # a spike
    kept = simplify(x, y)
    assert 700 in kept
    assert len(kept) < 400
    for a, b in itertools.pairwise(kept):  # every point left out: within 0.1 px of the segment drawn
        d = np.array([x[b] - x[a], y[b] - y[a]])
        o = np.stack([x[a + 1 : b] - x[a], y[a + 1 : b] - y[a]], axis=1)
        along = np.clip(o @ d / (d @ d), 0.0, 1.0)
        assert np.all(np.hypot(*(o - along[:, None] * d).T) <= 0.1 + 1e-9)


def _coordinates(svg: bytes) -> np.ndarray:
    """Every number in the figure's points, d, x, y, width and height attributes."""
    values = re.findall(rb' (?:points|d|x|y|width|height)="([^"]*)"', svg)
    return np.array([float(v) for attr in values for v in re.findall(rb"-?[\d.]+(?:e[-+]?\d+)?", attr)])


@pytest.mark.parametrize("spike", [1e40, -1e40, 1e200, -1e300, 1.7e308])
def test_a_far_out_value_draws_the_line_up_to_the_panel_edge(spike):
    """A browser holds coordinates as 32-bit floats: a polyline through y = 1e40 px vanished whole, and at 1e200 the
    simplification overflowed and dropped points inside the panel.  Cut at CLIP_MARGIN px beyond the panel, every
    coordinate is small, every point inside the panel drawn where it was, the spike drawn up to the panel's edge."""
    fig, ax = _one()
    x = np.arange(20.0)
    y = np.sin(x)
    y[10] = spike
    ax.line(x, y, decimate=False)
    ax.set_ylim(-1.5, 1.5)
    svg = fig.to_svg()
    assert np.abs(_coordinates(svg)).max() < max(fig.size) + CLIP_MARGIN
    (panel,) = panels(parse(svg))
    left, top, right, bottom = frame(panel)
    drawn = np.concatenate([points(p) for p in polylines(data(panel))])
    (((x0, x1), _),) = limits(fig.panels)
    for k in np.flatnonzero(np.arange(20) != 10):  # every point within the panel drawn, to 0.01 px
        px = left + (x[k] - x0) / (x1 - x0) * (right - left)
        py = bottom - (y[k] + 1.5) / 3.0 * (bottom - top)
        assert np.hypot(drawn[:, 0] - px, drawn[:, 1] - py).min() < 0.01
    edge = top - CLIP_MARGIN if spike > 0 else bottom + CLIP_MARGIN
    assert np.sum(np.abs(drawn[:, 1] - edge) < 0.01) == 2  # up to the window's edge and back: the spike


def test_a_line_at_1e200_keeps_its_points_inside_the_panel():
    fig, ax = _one()
    ax.line(np.arange(6.0), [0.0, 1e200, 0.0, 1.0, 2.0, 1.0], decimate=False)  # kept 3 points of 6
    ax.set_ylim(0.0, 2.0)
    (panel,) = panels(parse(fig.to_svg()))
    left, top, right, bottom = frame(panel)
    first, rest = (points(p) for p in polylines(data(panel)))
    (((x0, x1), _),) = limits(fig.panels)
    fx, fy = (lambda v: left + (v - x0) / (x1 - x0) * (right - left)), (lambda v: bottom - v / 2 * (bottom - top))
    # (0, 0) to (1, 1e200) rises straight up at x = 0 as drawn; (1, 1e200) to (2, 0) comes down at x = 2
    np.testing.assert_allclose(first, [[fx(0), bottom], [fx(0), top - CLIP_MARGIN]], atol=0.01)
    np.testing.assert_allclose(rest[0], [fx(2), top - CLIP_MARGIN], atol=0.01)
    # down to (2, 0), up through (3, 1) (on the way: left out) to (4, 2), down to (5, 1)
    np.testing.assert_allclose(rest[1:], [[fx(2), fy(0)], [fx(4), fy(2)], [fx(5), fy(1)]], atol=0.01)


def test_nan_still_breaks_a_line_cut_at_the_window():
    fig, ax = _one()
    ax.line(np.arange(7.0), [0.0, 1.0, np.nan, 1.0, 1e40, 1.0, 0.0], decimate=False)
    ax.set_ylim(0.0, 2.0)
    lines = polylines(data(panels(parse(fig.to_svg()))[0]))
    assert [len(points(p)) for p in lines] == [2, 2, 3]  # the NaN; out through the top and back


def _exact_cut(p, q, win):
    """The part of segment p-q within win, exactly (Fractions), or None."""
    from fractions import Fraction as F

    (x0, y0), (x1, y1) = (tuple(map(F, p)), tuple(map(F, q)))
    left, top, right, bottom = map(F, win)
    dx, dy = x1 - x0, y1 - y0
    t0, t1 = F(0), F(1)
    for a, b in ((-dx, x0 - left), (dx, right - x0), (-dy, y0 - top), (dy, bottom - y0)):
        if a == 0:
            if b < 0:
                return None
        elif a < 0:
            t0 = max(t0, b / a)
        else:
            t1 = min(t1, b / a)
    if t0 > t1:
        return None
    return [(float(x0 + t * dx), float(y0 + t * dy)) for t in (t0, t1)]


def test_clip_line_keeps_every_visible_part_exactly():
    """Random polylines with points far out along x or along y (1e12 .. 1e300 px): the runs drawn are the segments'
    parts within the window, exactly (to 1e-9 px against Fractions), broken where the line leaves it."""
    rng = np.random.default_rng(7)
    win = (0.0, 0.0, 600.0, 400.0)
    for _ in range(40):
        n = int(rng.integers(2, 30))
        px, py = rng.uniform(-300.0, 900.0, n), rng.uniform(-300.0, 700.0, n)
        far = rng.random(n) < 0.3
        axis = rng.random(n) < 0.5
        big = rng.choice([1e12, 1e40, 1e200, 1e300], n) * rng.choice([-1.0, 1.0], n)
        px, py = np.where(far & axis, big, px), np.where(far & ~axis, big, py)
        runs = clip_line(px, py, win)
        drawn = [(a, b) for x, y in runs for a, b in itertools.pairwise(zip(x.tolist(), y.tolist(), strict=True))]
        exact = [c for c in (_exact_cut(*pair, win) for pair in itertools.pairwise(zip(px, py, strict=True))) if c]
        exact = [c for c in exact if c[0] != c[1]]
        assert len(drawn) == len(exact)
        for (a, b), (ea, eb) in zip(drawn, exact, strict=True):
            assert np.hypot(a[0] - ea[0], a[1] - ea[1]) < 1e-9
            assert np.hypot(b[0] - eb[0], b[1] - eb[1]) < 1e-9
        cuts = [(x[-1], y[-1]) for x, y in runs[:-1]] + [(x[0], y[0]) for x, y in runs[1:]]
        assert all(x in (0.0, 600.0) or y in (0.0, 400.0) for x, y in cuts)  # broken only at the window's edge


def _winding(xs, ys, point):
    """How many times the polygon (xs, ys) winds round ``point``, exactly (Fractions)."""
    from fractions import Fraction as F

    px, py = map(F, point)
    total = 0
    for (x0, y0), (x1, y1) in itertools.pairwise([*zip(xs, ys, strict=True), (xs[0], ys[0])]):
        x0, y0, x1, y1 = F(x0), F(y0), F(x1), F(y1)
        side = (x1 - x0) * (py - y0) - (px - x0) * (y1 - y0)
        if y0 <= py < y1 and side > 0:
            total += 1
        elif y1 <= py < y0 and side < 0:
            total -= 1
    return total


def test_clip_polygon_covers_the_window_as_before():
    """A band with a spike to 1e40 and one to -1e300 (crossing itself): cut to the window, it covers every point of
    the window as often as before (exact winding numbers on a grid), and has no coordinate outside it."""
    x = np.array([0.0, 100.0, 200.0, 300.0, 400.0, 500.0, 600.0])
    hi = np.array([50.0, 80.0, 1e40, 120.0, 90.0, -1e300, 60.0])
    lo = np.array([150.0, 200.0, 180.0, 220.0, 200.0, 250.0, 30.0])
    xs, ys = np.concatenate([x, x[::-1]]), np.concatenate([hi, lo[::-1]])
    win = (50.0, 20.0, 550.0, 380.0)
    cx, cy = clip_polygon(xs, ys, win)
    assert np.all((cx >= 50) & (cx <= 550) & (cy >= 20) & (cy <= 380))
    grid = [(gx + 0.37, gy + 0.61) for gx in range(50, 550, 23) for gy in range(20, 380, 17)]
    assert [_winding(cx, cy, g) for g in grid] == [_winding(xs, ys, g) for g in grid]
    assert len(clip_polygon(xs + 1e4, ys, win)[0]) == 0  # outside: nothing


def test_far_out_spans_bars_markers_and_text_stay_near_the_panel():
    fig, ax = _one()
    ax.line([0.0, 1.0], [0.0, 1.0])
    ax.hspan(0.5, 1e300)
    ax.bars([0.5], [-1e40], width=0.2, colors="C2")
    ax.band([0.0, 1.0], [-1e40, 0.0], [1e40, 1.0])
    ax.markers([0.2, 0.4], [1e40, 0.5])
    ax.text(0.5, 1e40, "far")
    ax.set_ylim(0.0, 1.0)
    svg = fig.to_svg()
    assert np.abs(_coordinates(svg)).max() < max(fig.size) + CLIP_MARGIN
    (panel,) = panels(parse(svg))
    _, top, _, bottom = frame(panel)
    span = next(r for r in data(panel).iter(f"{NS}rect") if r.get("fill-opacity") == "0.2")
    assert float(span.get("y")) == pytest.approx(top - CLIP_MARGIN)  # up past the panel's top
    assert float(span.get("y")) + float(span.get("height")) == pytest.approx((top + bottom) / 2)
    bar = next(r for r in data(panel).iter(f"{NS}rect") if r.get("fill") == TAB10[2])
    assert (float(bar.get("y")), float(bar.get("height"))) == (pytest.approx(bottom), pytest.approx(CLIP_MARGIN))
    (marker,) = [p for p in data(panel).iter(f"{NS}path") if p.get("fill") == TAB10[0]]
    assert marker.get("d").count("M") == 1  # the one within reach
    assert "far" not in texts(panel)


def test_rules_spans_bands_bars_markers():
    fig, ax = _one()
    ax.hline(1.0, color="0.45", dash="--", label="dashed")
    ax.vline(2.0, color="C2", dash=":")
    ax.hspan(-2.0, 2.0, color="C3", opacity=0.18, label="band")
    ax.band([0, 1, 2, 3], [0, 0, np.nan, 0], [1, 1, np.nan, 1])
    ax.bars([0, 1, 2], [1.0, np.nan, 3.0], colors=["C0", "C1", "C3"])
    ax.markers([1.0], [1.0], shape="s", color="C3")
    ax.markers([0.5], [4.0], shape="^", color="C1", clip=False)
    root = parse(fig.to_svg())
    (panel,) = panels(root)
    inside = data(panel)
    dashes = [p for p in inside.iter(f"{NS}path") if p.get("stroke-dasharray")]
    assert {p.get("stroke") for p in dashes} == {"#737373", TAB10[2]}
    assert len(inside.findall(f"{NS}polygon")) == 1  # the band's NaN leaves one piece, and a lone point:
    (lone,) = [r for r in inside.findall(f"{NS}rect") if r.get("fill-opacity") == "0.25"]  # a bar 6 px wide
    assert float(lone.get("width")) == 6.0
    assert float(lone.get("height")) > 0
    bars = [r for r in inside.findall(f"{NS}rect") if r.get("fill") in TAB10 and not r.get("fill-opacity")]
    assert sorted(r.get("fill") for r in bars) == sorted([TAB10[0], TAB10[3]])  # NaN: no bar
    assert any(r.get("fill-opacity") == "0.18" for r in inside.findall(f"{NS}rect"))
    unclipped = [p for p in panel.findall(f"{NS}path") if p.get("fill") == TAB10[1]]
    assert len(unclipped) == 1  # the marker outside the clip
    assert legend_texts(root) == []  # no legend asked for


def test_corner_legend_goes_where_the_data_are_not():
    fig, ax = _one()
    t = np.linspace(0, 1, 200)
    ax.line(t, t, label="rising")  # lower left to upper right: the upper left and lower right are empty
    ax.line(t, np.where(t < 0.5, 1.0, np.nan), label="high early")  # fills the upper left
    ax.legend("best")
    root = parse(fig.to_svg())
    (panel,) = panels(root)
    legend = next(g for g in panel.iter(f"{NS}g") if g.get("class") == "legend")
    box = legend.find(f"{NS}rect")
    left, top, right, bottom = frame(panel)
    assert float(box.get("x")) > (left + right) / 2  # right ...
    assert float(box.get("y")) > (top + bottom) / 2  # ... and below: the lower right
    assert legend_texts(root) == ["rising", "high early"]


def test_legend_below_wraps_into_rows_and_the_figure_grows():
    fig, ax = _one()
    for k in range(12):
        ax.line([0, 1], [k, k], color=f"C{k % 10}", label=f"a rather long legend entry number {k}")
    fig.legend_below(fig.entries())
    root = parse(fig.to_svg())
    assert float(root.get("height")) > 3.0 * PX_PER_INCH  # more than one row: taller
    assert len(legend_texts(root)) == 12
    rows = {round(float(t.get("y"))) for g in root.findall(f"{NS}g[@class='legend']") for t in g.iter(f"{NS}text")}
    assert len(rows) > 1
    assert max(float(t.get("x")) for t in root.iter(f"{NS}text")) < 6.0 * PX_PER_INCH


def test_shared_axes_label_the_outer_ticks_only():
    fig = Figure((6.0, 5.0), grid=(2, 2), gaps=(0.5, 0.4), sharex=True, sharey=True)
    for k, ax in enumerate(fig.panels):
        ax.line([0, 10 + k], [0, 5 - k])
    fig.remove(fig.panels[3])  # an unused cell: the panel above it shows the x ticks
    root = parse(fig.to_svg())
    shown = panels(root)
    assert len(shown) == 3
    assert [bool(tick_labels(p, "x")) for p in shown] == [False, True, True]
    assert [bool(tick_labels(p, "y")) for p in shown] == [True, False, True]
    assert len({lim for lim in limits(fig.visible, True, True)}) == 1


def test_equal_aspect():
    fig, ax = _one()
    ax.line([0, 4], [0, 1])
    ax.equal = True
    ((xlim, ylim),) = limits(fig.visible)
    _, _, w, h = ax.box
    assert (xlim[1] - xlim[0]) / w == pytest.approx((ylim[1] - ylim[0]) / h)
    assert xlim[0] < 0 < 4 < xlim[1]
    assert ylim[0] < 0 < 1 < ylim[1]


def test_log_axis_labels_decades():
    fig, ax = _one()
    ax.line(np.linspace(0, 1, 50), np.logspace(-6, 2, 50))
    ax.y.scale = "log"
    labels = tick_labels(panels(parse(fig.to_svg()))[0], "y")
    assert "10⁻⁶" in labels or "10⁻⁵" in labels
    assert "10²" in labels or "10¹" in labels
    assert all(re.fullmatch("10[⁻⁰¹²³⁴⁵⁶⁷⁸⁹]+", label) for label in labels)
    fig, ax = _one()
    ax.line([0.0, 1.0, 2.0], [-1.0, 0.0, 1.0])  # nothing but one positive value on a log axis: no error
    ax.y.scale = "log"
    parse(fig.to_svg())


@pytest.mark.parametrize(
    "start", [dt.datetime(1, 1, 1), dt.datetime(2026, 12, 6), dt.datetime(9999, 11, 20)], ids=["year 1", "now", "9999"]
)
def test_date_axis_at_any_date(start):
    fig, ax = _one()
    x = [date_number(start + dt.timedelta(days=d)) for d in range(40)]
    ax.line(x, np.arange(40.0))
    ax.x.scale = "date"
    labels = tick_labels(panels(parse(fig.to_svg()))[0], "x")
    assert len(labels) >= 2
    assert all(re.fullmatch(r"\d{4}(-\d{2}){0,2}", label) for label in labels), labels
    assert all(label[:4] == f"{start.year:04d}" or label[:4] == f"{start.year + 1:04d}" for label in labels)


def test_date_labels_stay_inside_the_figure_and_points_clear_of_the_edges():
    """A 2.2-inch panel of three days from year 1: "0001-01-03" was centred on its tick near the right edge and cut
    by the figure's edge; points on the calendar's first day sat on the panel's edge, half clipped."""
    fig = Figure((3.2, 2.0))  # margins 0.8 and 0.2 inch: a panel 2.2 inches wide
    ax = fig.panels[0]
    ax.markers([date_number(dt.datetime(1, 1, 1 + d)) for d in range(3)], [0.0, 1.0, 2.0])
    ax.x.scale = "date"
    (panel,) = panels(parse(fig.to_svg()))
    labels = [t for t in panel.findall(f"{NS}text") if t.get("y") and float(t.get("y")) > frame(panel)[3]]
    assert [t.text for t in labels] == ["0001-01-01", "0001-01-03"]
    for t in labels:
        half = text_width(t.text, float(t.get("font-size"))) / 2
        assert half <= float(t.get("x")) <= fig.width - half
    left, _, right, _ = frame(panel)
    (dots,) = data(panel).findall(f"{NS}path")
    starts = [float(v) for v in re.findall(r"M([\d.]+),", dots.get("d"))]  # each circle's left, 8 px across
    assert left < min(starts)
    assert max(starts) + 8.0 < right


@pytest.mark.parametrize(("lim", "labels"), [((-0.5, 0.5), ["0"]), ((-0.5, 1.5), ["0", "1"]), ((0.0, 3.0), None)])
def test_an_integer_axis_has_whole_numbers_only(lim, labels):
    fig, ax = _one()
    ax.markers([0.0], [0.0])
    ax.x.integer = True
    ax.set_xlim(*lim)
    got = tick_labels(panels(parse(fig.to_svg()))[0], "x")
    assert got == (labels or ["0", "1", "2", "3"])
    ax.x.integer = False
    assert len(tick_labels(panels(parse(fig.to_svg()))[0], "x")) > len(got)  # (0.5 steps and finer otherwise)


def test_colours():
    assert colour("C0") == "#1f77b4"
    assert colour("C1") == "#ff7f0e"
    assert colour("k") == "#000000"
    assert colour("0.75") == "#bfbfbf"
    assert (diverging(1.0), diverging(-1.0), diverging(0.0)) == ("#67001f", "#053061", "#f7f7f7")
    assert diverging(5.0) == RDBU_R[-1]  # clipped
    assert diverging(float("nan")) == MISSING
    assert luminance("#67001f") < 0.5 < luminance("#f7f7f7")
    assert (num(1.0), num(-0.001), num(2.345), num(1056.0)) == ("1", "0", "2.35", "1056")


@pytest.mark.parametrize(
    ("x", "y", "lim"),
    [
        ([], [], None),  # nothing to draw
        ([0.0, 1.0, 2.0], [np.nan] * 3, None),  # nothing finite
        ([0.0, 1.0, 2.0], [3.0, 3.0, 3.0], None),  # a constant
        ([5.0], [2.0], None),  # a single sample
        ([0.0, 1.0], [1.0, 2.0], (4.0, 4.0)),  # limits that are one value
        ([1e300, 1.0000001e300], [-1e-300, 1e-300], None),  # huge and tiny
    ],
)
def test_degenerate_data_draw(x, y, lim):
    fig, ax = _one(sharex=True)
    ax.line(x, y, label="x")
    ax.markers(x, y)
    if lim:
        ax.set_xlim(*lim)
        ax.set_ylim(*lim)
    ax.legend()
    root = parse(fig.to_svg())
    (panel,) = panels(root)
    assert tick_labels(panel, "x")
    assert tick_labels(panel, "y")
    assert not any(s in fig.to_svg() for s in (b"nan", b"inf"))


TINY, HUGE = 5e-324, 1.7976931348623157e308  # the smallest positive float (subnormal) and the largest


@pytest.mark.parametrize(
    ("y", "scale"),
    [
        ([1e-300, 1e300], "log"),  # 10^(300 + pad) overflowed
        ([TINY, 1.0], "log"),  # 10^(-323 - pad) underflowed to 0: log10(0)
        ([TINY, HUGE], "log"),
        ([HUGE, HUGE], "log"),
        ([TINY, TINY], "log"),
        ([-8.5e307, 8.5e307], "linear"),  # floor(log10(inf))
        ([-1e308, 1e308], "linear"),  # the limits' span inf: NaN px, nothing drawn
        ([-HUGE, HUGE], "linear"),
        ([HUGE, HUGE], "linear"),
        ([-HUGE, -HUGE], "linear"),
        ([0.0, TINY], "linear"),
        ([1.0, 1.0 + 2.0**-52], "linear"),  # closer than a tick step tells apart: widened
    ],
)
def test_any_finite_data_draw_with_ticks(y, scale):
    """Limits, ticks and px for the extremes of the floats: no exception, every point drawn inside the panel, ticks
    labelled within the limits."""
    fig, ax = _one()
    ax.line([0.0, 1.0], y, decimate=False)
    ax.markers([0.0, 1.0], y, shape="s")
    ax.y.scale = scale
    (((_, _), (lo, hi)),) = limits(fig.panels)
    assert 0 < lo < hi < math.inf if scale == "log" else -math.inf < lo < hi < math.inf
    svg = fig.to_svg()
    assert not any(s in svg for s in (b"nan", b"inf"))
    (panel,) = panels(parse(svg))
    left, top, right, bottom = frame(panel)
    (line,) = polylines(data(panel))
    xy = points(line)
    assert len(xy) == 2
    assert np.all((xy[:, 0] >= left) & (xy[:, 0] <= right) & (xy[:, 1] >= top) & (xy[:, 1] <= bottom))
    assert tick_labels(panel, "y")
    ticks = [float(y) for _, y in re.findall(r"M([\d.]+),([\d.]+)h-4", svg.decode())]
    assert ticks
    assert all(top - 0.01 <= t <= bottom + 0.01 for t in ticks)


@settings(max_examples=60, deadline=None)
@given(
    y=st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=1, max_size=4),
    scale=st.sampled_from(["linear", "log"]),
)
def test_any_finite_data_draw(y, scale):
    fig, ax = _one()
    ax.line(np.arange(len(y)), y, decimate=False)
    ax.markers(np.arange(len(y)), y)
    ax.y.scale = scale
    svg = fig.to_svg()
    assert not any(s in svg for s in (b"nan", b"inf"))
    if scale == "linear" or max(y) > 0:
        assert tick_labels(panels(parse(svg))[0], "y")


def test_bad_styles_are_usage_errors():
    from wmrid.core.errors import UsageError

    fig, ax = _one()
    with pytest.raises(UsageError, match="shape"):
        ax.markers([0], [0], shape="*")
    with pytest.raises(UsageError, match="dash"):
        ax.line([0, 1], [0, 1], dash="..")
    with pytest.raises(UsageError, match="one length"):
        ax.line([0, 1], [0, 1, 2])
    with pytest.raises(UsageError, match="corner"):
        ax.legend("middle")
    with pytest.raises(UsageError, match="colour"):
        colour("reddish")
    ax.line([1, 2], [1, 2])
    ax.y.scale = "log"
    ax.set_ylim(-1.0, 10.0)
    with pytest.raises(UsageError, match="positive"):
        fig.to_svg()
