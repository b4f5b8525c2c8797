"""A figure of :mod:`wmrid.reporting.svg` drawn: each panel's grid, clipped artists, frame, ticks, labels, title and
legend, then the legend rows below the panels (:func:`draw_figure`)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from wmrid.core.errors import UsageError
from wmrid.reporting.svg_artists import Bars, Entry, Frame, Line, Markers, Rule, legend_handle, text_element
from wmrid.reporting.svg_axes import (
    DATE_RANGE,
    FLOAT_MAX,
    FLOAT_TINY,
    date_ticks,
    degenerate,
    linear_labels,
    linear_ticks,
    log_ticks,
    pow10,
    text_width,
)
from wmrid.reporting.svg_panel import Axis, Panel
from wmrid.reporting.svg_style import ID_PLACEHOLDER as _ID, PAD as _PAD, SMALL, num

_GRID = 'stroke="#b0b0b0" stroke-opacity="0.35" stroke-width="0.8"'
_HANDLE = 24.0  # legend sample length, px


def limits(
    panels: Sequence[Panel], sharex: bool = False, sharey: bool = False
) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """The limits each panel is drawn with.

    Parameters
    ----------
    panels
        A figure's panels shown (:attr:`wmrid.reporting.svg.Figure.visible`).
    sharex, sharey
        One x (y) range for every panel: the first set, else the data's of them all.

    Returns
    -------
    list of ((x0, x1), (y0, y1))
        Per panel, in the axes' units: set, shared, or from the data (:func:`data_limits`), then widened for an equal
        aspect where the panel asks for one.
    """
    shared_x = data_limits(panels, "x") if sharex and panels else None
    shared_y = data_limits(panels, "y") if sharey and panels else None
    out = []
    for panel in panels:
        xlim = shared_x or data_limits([panel], "x")
        ylim = shared_y or data_limits([panel], "y")
        out.append(_equal(panel, xlim, ylim) if panel.equal else (xlim, ylim))
    return out


def draw_figure(
    panels: Sequence[Panel], *, sharex: bool, sharey: bool, below: Sequence[Entry], size: tuple[float, float]
) -> tuple[str, float]:
    """A figure's SVG body.

    Parameters
    ----------
    panels
        The panels shown.
    sharex, sharey
        One x (y) range for all, its tick labels only at the bottom of a column (at the left of a row).
    below
        Legend entries drawn in rows below the panels.
    size
        The figure's (width, height), px.

    Returns
    -------
    body : str
        Its elements (ids prefixed by :data:`~wmrid.reporting.svg_style.ID_PLACEHOLDER`, which the figure replaces):
        each panel a ``<g class="panel">`` with its data in a ``<g>`` clipped to its box, a legend a
        ``<g class="legend">``.
    height : float
        The figure's height, px: taller than ``size`` when the legend below needs more than one row.
    """
    defs, parts = [], []
    for k, (panel, (xlim, ylim)) in enumerate(zip(panels, limits(panels, sharex, sharey), strict=True)):
        x_labels = panel.x.labels_visible and not (
            sharex and panel.cell is not None
            and any(q.cell is not None and q.cell[1] == panel.cell[1] and q.cell[0] > panel.cell[0] for q in panels)
        )  # fmt: skip
        y_labels = panel.y.labels_visible and not (
            sharey and panel.cell is not None
            and any(q.cell is not None and q.cell[0] == panel.cell[0] and q.cell[1] < panel.cell[1] for q in panels)
        )  # fmt: skip
        left, top, w, h = panel.box
        defs.append(f'<clipPath id="{_ID}c{k}"><rect x="{num(left)}" y="{num(top)}" width="{num(w)}" '
                    f'height="{num(h)}"/></clipPath>')  # fmt: skip
        parts.append(_draw_panel(panel, xlim, ylim, f"{_ID}p{k}", f"{_ID}c{k}", (x_labels, y_labels), size[0]))
    body, height = "".join(parts), size[1]
    if below:
        legend, height = _legend_rows(list(below), size[0], size[1])
        body += legend
    return f"<defs>{''.join(defs)}</defs>\n{body}", height


def _equal(
    panel: Panel, xlim: tuple[float, float], ylim: tuple[float, float]
) -> tuple[tuple[float, float], tuple[float, float]]:
    """Limits widened so that a unit of x and of y take the same px (the panel's box kept; within ±FLOAT_MAX)."""
    _, _, w, h = panel.box
    (x0, x1), (y0, y1) = xlim, ylim
    half_per_px = max((x1 / 2 - x0 / 2) / w, (y1 / 2 - y0 / 2) / h)  # halves: no overflow
    cx, cy = x0 / 2 + x1 / 2, y0 / 2 + y1 / 2

    def around(c: float, px: float) -> tuple[float, float]:
        return max(c - half_per_px * px, -FLOAT_MAX), min(c + half_per_px * px, FLOAT_MAX)

    return around(cx, w), around(cy, h)


def _draw_panel(
    panel: Panel, xlim: tuple[float, float], ylim: tuple[float, float], ident: str, clip: str,
    show: tuple[bool, bool], width: float,
) -> str:  # fmt: skip
    """One panel: grid, clipped artists, frame, ticks, tick labels (``show``: of x, of y; an x label that would
    cross the edge of the figure, ``width`` px wide, moved in), labels, title, legend."""
    left, top, w, h = panel.box
    right, bottom = left + w, top + h
    fx = panel.x.mapping(xlim[0], xlim[1], left, right)
    fy = panel.y.mapping(ylim[0], ylim[1], bottom, top)
    frame = Frame(fx, fy, (left, top, right, bottom), ident)
    xt, xl, xminor, xnote = axis_ticks(panel.x, xlim[0], xlim[1], w, True)
    yt, yl, yminor, ynote = axis_ticks(panel.y, ylim[0], ylim[1], h, False)
    px, py = fx(xt), fy(yt)
    out = ['<g class="panel">']
    grid = ""
    if "x" in panel.grid:
        grid += "".join(f"M{num(x)},{num(top)}V{num(bottom)}" for x in px)
    if "y" in panel.grid:
        grid += "".join(f"M{num(left)},{num(y)}H{num(right)}" for y in py)
    if grid:
        out.append(f'<path d="{grid}" fill="none" {_GRID}/>')
    artists = sorted(panel.artists, key=lambda a: a.zorder)
    clipped = "".join(a.draw(frame) for a in artists if not (isinstance(a, Markers) and not a.clip))
    out.append(f'<g clip-path="url(#{clip})">{clipped}</g>')
    out += [a.draw(frame) for a in artists if isinstance(a, Markers) and not a.clip]
    if panel.frame:
        out.append(f'<rect x="{num(left)}" y="{num(top)}" width="{num(w)}" height="{num(h)}" fill="none" '
                   'stroke="#000000" stroke-width="0.8"/>')  # fmt: skip
    out.append(_ticks(panel, px, py, fx(xminor), fy(yminor)))
    x_room = _PAD
    if show[0]:
        for x, label in zip(px, xl, strict=True):
            half = text_width(label, panel.x.size) / 2 + 1.0
            x = min(max(x, half), width - half) if width > 2 * half else width / 2  # within the figure
            out.append(text_element(x, bottom + panel.x.tick_length + _PAD, label, panel.x.size, valign="top"))
        lines = max((label.count("\n") + 1 for label in xl), default=1)
        x_room += panel.x.tick_length + lines * 1.2 * panel.x.size
        if xnote:
            out.append(text_element(right, bottom + x_room + _PAD, xnote, panel.x.size, anchor="end", valign="top"))
    widest = 0.0
    right_side = panel.y.side == "right"
    edge, outward = (right, 1.0) if right_side else (left, -1.0)
    if show[1]:
        for y, label in zip(py, yl, strict=True):
            out.append(text_element(edge + outward * (panel.y.tick_length + _PAD), y, label, panel.y.size,
                                    anchor="start" if right_side else "end", valign="center"))  # fmt: skip
        widest = max((text_width(label, panel.y.size) for label in yl), default=0.0)
        if ynote:
            out.append(text_element(left, top - _PAD, ynote, panel.y.size))
    if panel.x.label:
        size = _fitted(panel.x.label, panel.x.label_size, w)
        out.append(text_element((left + right) / 2, bottom + x_room + _PAD, panel.x.label, size, valign="top"))
    if panel.y.label:
        size = _fitted(panel.y.label, panel.y.label_size, h)
        if right_side:  # the text reads upwards: its glyphs lie left of its baseline
            x = right + panel.y.tick_length + 2 * _PAD + widest + 0.8 * size
        else:
            x = max(left - panel.y.tick_length - 2 * _PAD - widest - 0.25 * size, 0.85 * size + 1.0)
        out.append(text_element(x, (top + bottom) / 2, panel.y.label, size, rotate=True))
    if panel.title:
        above = top - (_PAD + 2 + (panel.y.size if ynote else 0.0))
        size = _fitted(panel.title, panel.title_size, 1.1 * w)
        out.append(text_element((left + right) / 2, above, panel.title, size, color=panel.title_color))
    if panel.legend_loc:
        out.append(_corner_legend(panel, frame))
    out.append("</g>\n")
    return "".join(out)


def _fitted(text: str, size: float, room: float) -> float:
    """The font size (px) at which ``text`` fits ``room`` px: ``size``, or smaller (down to 8 px)."""
    width = text_width(text, size)
    return size if width <= room else max(8.0, size * room / width)


def _ticks(panel: Panel, px: np.ndarray, py: np.ndarray, x_minor: np.ndarray, y_minor: np.ndarray) -> str:
    left, top, w, h = panel.box
    bottom = top + h
    d: list[str] = []
    lx, ly = panel.x.tick_length, panel.y.tick_length
    if lx:
        d += [f"M{num(x)},{num(bottom)}v{num(lx)}" for x in px]
        d += [f"M{num(x)},{num(bottom)}v{num(lx / 2)}" for x in x_minor]
    if ly:
        edge, ly = (left + w, ly) if panel.y.side == "right" else (left, -ly)
        d += [f"M{num(edge)},{num(y)}h{num(ly)}" for y in py]
        d += [f"M{num(edge)},{num(y)}h{num(ly / 2)}" for y in y_minor]
    return f'<path d="{"".join(d)}" stroke="#000000" stroke-width="0.8"/>' if d else ""


def _entry_width(entry: Entry, size: float) -> float:
    handle = 0.0 if entry[0] == "text" else _HANDLE + 6.0
    return handle + text_width(entry[2], size)


def _entry(entry: Entry, x: float, y: float, size: float) -> str:
    kind, style, label = entry
    out = legend_handle(kind, style, x, y, _HANDLE)
    shift = 0.0 if kind == "text" else _HANDLE + 6.0
    return out + text_element(x + shift, y, label, size, anchor="start", valign="center")


def _legend_rows(entries: list[Entry], width: float, height: float) -> tuple[str, float]:
    """The entries in centred rows along the bottom edge; the figure's new height when they need several rows."""
    gap, row_h = 22.0, 1.7 * SMALL
    rows: list[list[Entry]] = [[]]
    used = 0.0
    for e in entries:
        w = _entry_width(e, SMALL)
        if rows[-1] and used + gap + w > width - 20.0:
            rows.append([])
            used = 0.0
        used += (gap if rows[-1] else 0.0) + w
        rows[-1].append(e)
    height += (len(rows) - 1) * row_h
    out = []
    for k, row in enumerate(rows):
        y = height - 0.9 * SMALL - (len(rows) - 1 - k) * row_h
        total = sum(_entry_width(e, SMALL) for e in row) + gap * (len(row) - 1)
        x = (width - total) / 2
        for e in row:
            out.append(_entry(e, x, y, SMALL))
            x += _entry_width(e, SMALL) + gap
    return f'<g class="legend">{"".join(out)}</g>\n', height


_CORNERS = ("upper right", "upper left", "lower left", "lower right")


def _corner_legend(panel: Panel, frame: Frame) -> str:
    entries = panel.entries()
    if not entries:
        return ""
    size = panel.legend_size
    row_h = 1.45 * size
    box_w = max(_entry_width(e, size) for e in entries) + 16.0
    box_h = len(entries) * row_h + 8.0
    left, top, right, bottom = frame.box
    inset = 6.0

    def corner(loc: str) -> tuple[float, float]:
        x = right - inset - box_w if "right" in loc else left + inset
        y = top + inset if "upper" in loc else bottom - inset - box_h
        return x, y

    loc = panel.legend_loc or "best"
    if loc == "best":
        xs, ys = _drawn_points(panel, frame)
        counts = []
        for c in _CORNERS:
            x0, y0 = corner(c)
            counts.append(int(np.count_nonzero((xs >= x0) & (xs <= x0 + box_w) & (ys >= y0) & (ys <= y0 + box_h))))
        loc = _CORNERS[int(np.argmin(counts))]
    x0, y0 = corner(loc)
    out = [f'<g class="legend"><rect x="{num(x0)}" y="{num(y0)}" width="{num(box_w)}" height="{num(box_h)}" rx="2" '
           'fill="#ffffff" fill-opacity="0.85" stroke="#cccccc" stroke-width="0.8"/>']  # fmt: skip
    for k, e in enumerate(entries):
        out.append(_entry(e, x0 + 8.0, y0 + 4.0 + (k + 0.5) * row_h, size))
    return "".join(out) + "</g>"


def _drawn_points(panel: Panel, frame: Frame) -> tuple[np.ndarray, np.ndarray]:
    """px of the points the panel's lines, markers and rules pass through (short lines sampled along their length),
    for the legend's "best" corner."""
    xs, ys = [], []
    left, top, right, bottom = frame.box
    for a in panel.artists:
        if isinstance(a, Line | Markers):
            px, py = frame.fx(a.x), frame.fy(a.y)
            if isinstance(a, Line) and 1 < len(px) < 400:
                k = np.linspace(0, len(px) - 1, 400)
                px, py = np.interp(k, np.arange(len(px)), px), np.interp(k, np.arange(len(py)), py)
        elif isinstance(a, Bars):  # a 5 x 5 grid of points on each bar
            f_along, f_value = (frame.fy, frame.fx) if a.horizontal else (frame.fx, frame.fy)
            s = np.linspace(-0.5, 0.5, 5)
            along = f_along((a.positions[:, None] + s[None, :] * a.width).ravel())
            base = f_value(np.zeros(1))[0]
            edge = (left if a.horizontal else bottom) if not np.isfinite(base) else base
            value = f_value(a.values)
            ends = edge + (value[:, None] - edge) * np.linspace(0.0, 1.0, 5)[None, :]
            grid_a = np.repeat(along.reshape(len(value), 5), 5, axis=1).ravel()
            grid_v = np.tile(ends, (1, 5)).ravel()
            px, py = (grid_v, grid_a) if a.horizontal else (grid_a, grid_v)
        elif isinstance(a, Rule):
            s = np.linspace(0.0, 1.0, 100)
            if a.axis == "y":
                px, py = left + s * (right - left), np.full(100, frame.fy(np.array([a.value]))[0])
            else:
                px, py = np.full(100, frame.fx(np.array([a.value]))[0]), top + s * (bottom - top)
        else:
            continue
        xs.append(px)
        ys.append(py)
    if not xs:
        return np.array([]), np.array([])
    return np.concatenate(xs), np.concatenate(ys)


def data_limits(panels: Sequence[Panel], axis: str) -> tuple[float, float]:
    """The limits of one axis over some panels.

    Parameters
    ----------
    panels
        One panel, or the panels sharing the axis (their scale is the first's).
    axis
        "x" or "y".

    Returns
    -------
    (lo, hi)
        The first limits set explicitly, else the data's range with 5 % margins (in log10 on a log axis, within the
        positive floats; of the data within years 1..9999 on a date axis, the margins beyond them too, so that a
        point on the calendar's first or last day stands clear of the edge); a single value, or values as close as
        :func:`~wmrid.reporting.svg_axes.degenerate` says, widened (by a day on a date axis).  Finite for any finite
        data.

    Raises
    ------
    UsageError
        Limits set on a log axis that are not both positive.
    """
    first = panels[0].x if axis == "x" else panels[0].y
    pinned: list[np.ndarray] = []
    for p in panels:
        lim = (p.x if axis == "x" else p.y).lim
        if lim is not None:
            if first.scale == "log" and min(lim) <= 0:
                raise UsageError(f"a log axis' limits must be positive, got {lim}")
            if lim[0] != lim[1]:
                return lim
            pinned = [np.asarray(lim, dtype=np.float64)]  # nothing between them: widened as a single value is
            break
    values = [a.extent()[0 if axis == "x" else 1] for p in panels for a in p.artists] + pinned
    v = np.concatenate([np.asarray(x, dtype=np.float64).ravel() for x in values]) if values else np.array([])
    v = v[np.isfinite(v) & ((v > 0) if first.scale == "log" else True)]
    if first.scale == "log":
        if len(v) == 0:
            return 1.0, 10.0
        a, b = math.log10(float(v.min())), math.log10(float(v.max()))
        pad = 0.05 * (b - a) if b > a else 0.5
        return max(pow10(a - pad), FLOAT_TINY), min(pow10(b + pad), FLOAT_MAX)
    if len(v) == 0:
        return 0.0, 1.0
    if first.scale == "date":
        v = np.clip(v, *DATE_RANGE)
    lo, hi = float(v.min()), float(v.max())
    if degenerate(lo, hi):
        pad = 1.0 if first.scale == "date" else max(0.05 * abs(lo / 2 + hi / 2), 0.5)
    else:
        pad = 0.1 * (hi / 2 - lo / 2)  # 5 % of the span, which may be beyond FLOAT_MAX
    return max(lo - pad, -FLOAT_MAX), min(hi + pad, FLOAT_MAX)


def axis_ticks(
    axis: Axis, lo: float, hi: float, length: float, horizontal: bool
) -> tuple[np.ndarray, list[str], np.ndarray, str]:
    """The ticks of one axis.

    Parameters
    ----------
    axis
        The axis (its scale, explicit ticks, label size).
    lo, hi
        Its limits, in its units.
    length
        Its length, px.
    horizontal
        An x axis (labels side by side: their widths set the spacing), else a y axis (one label height and a gap).

    Returns
    -------
    major : (n,) float
        Ticks labelled: the explicit ones within the limits, decades (:func:`~wmrid.reporting.svg_axes.log_ticks`),
        calendar units (:func:`~wmrid.reporting.svg_axes.date_ticks`), or nice linear steps whose labels do not touch.
    labels : list of str
        Their labels.
    minor : (m,) float
        Unlabelled ticks (a log axis' 2..9 x 10^k).
    note : str
        What completes the labels (a power of ten, an offset), or "".
    """
    a, b = min(lo, hi), max(lo, hi)
    if axis.ticks is not None:
        pos, labels = axis.ticks
        tol = 2e-9 * (b / 2 - a / 2)
        keep = [k for k, v in enumerate(pos) if a - tol <= v <= b + tol]
        return np.array([pos[k] for k in keep]), [labels[k] for k in keep], np.array([]), ""
    size = axis.size
    if axis.scale == "date":
        ticks, labels = date_ticks(a, b, length, size)
        return ticks, labels, np.array([]), ""
    if axis.scale == "log":
        room = text_width("10⁻¹⁰", size) + size if horizontal else 2.2 * size
        major, labels, minor = log_ticks(a, b, max(2, int(length // room)))
        return major, labels, minor, ""
    most = max(3, int(length // (4.5 * size)) + 1) if horizontal else max(2, int(length // (2.5 * size)) + 1)
    while True:
        ticks, step = linear_ticks(a, b, most, 1.0 if axis.integer else 0.0)
        ticks = ticks[(ticks >= a - 1e-9 * step) & (ticks <= b + 1e-9 * step)]  # limits set closer than a step
        labels, note = linear_labels(ticks, step)
        spacing = (step / 2) / (b / 2 - a / 2) * length if b > a else length
        need = max(text_width(t, size) for t in labels) + 0.8 * size if horizontal and labels else 1.6 * size
        if spacing >= need or most <= 2 or len(ticks) <= 2:
            return ticks, labels, np.array([]), note
        most = len(ticks) - 1
