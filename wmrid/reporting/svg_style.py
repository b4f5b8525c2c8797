"""The style of wmrid's SVG figures (:mod:`wmrid.reporting.svg`): font sizes, colours (the Tableau 10 palette
C0..C9, greys, a diverging red-blue scale), dash patterns, and how numbers, text, polylines and polygons are written
into SVG (2 decimals; escaped; split where a value is missing, cut at a window around the panel, simplified to within
0.1 px)."""

from __future__ import annotations

import math
import re

import numpy as np

from wmrid.core.errors import UsageError
from wmrid.core.xml_chars import XML_FORBIDDEN

#: The Tableau 10 palette, named C0 ... C9 as the figures have always called them: right wheel C0 (blue), left
#: wheel C1 (orange).
TAB10 = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf")
_NAMED = {"k": "#000000", "black": "#000000", "white": "#ffffff", "w": "#ffffff", "none": "none"}
#: Dash patterns (dash, gap, ...), in units of the line's width.
_DASHES = {"--": (3.7, 1.6), ":": (1.0, 1.65), "-.": (6.4, 1.6, 1.0, 1.6)}
#: Font sizes, px: tick labels and axis labels, legends and small labels, panel titles.
FONT, SMALL, TITLE = 13.0, 11.5, 14.5
#: Tick length and the padding between a panel's parts, px.
TICK, PAD = 4.0, 3.0
#: Stands for the id prefix of a figure's elements until the figure's content gives it (never in escaped text).
ID_PLACEHOLDER = "<id>"
#: px as far as a panel's mapping goes (:meth:`wmrid.reporting.svg_panel.Axis.mapping`): a value beyond is held here,
#: so that px stay finite (and differences of px too) whatever the data.
FAR = 1e300
#: How far beyond its panel's box a line, band, span, bar or cell is drawn, px: cut there (:func:`window`), so that
#: every coordinate written lies within about this of the figure.  Browsers hold SVG coordinates as 32-bit floats and
#: drop a whole polyline with a point at 1e40; near 1000 px a 32-bit float still resolves 1e-4 px.  Far more than a
#: stroke's half width: the cut never shows (the panel clips its data at its box).
CLIP_MARGIN = 1000.0

#: A drawing window: (left, top, right, bottom) px.
Window = tuple[float, float, float, float]


def colour(name: str) -> str:
    """An SVG colour from a short name.

    Parameters
    ----------
    name
        ``C0`` .. ``C9`` (:data:`TAB10`), ``k``/``black``, ``w``/``white``, ``none``, a grey level ``"0.45"``
        (0 black .. 1 white), or ``#rrggbb`` (kept).

    Returns
    -------
    str
        ``#rrggbb`` (or ``none``).

    Raises
    ------
    UsageError
        A name that is none of these.
    """
    if re.fullmatch(r"#[0-9a-fA-F]{6}", name) or name == "none":
        return name
    if re.fullmatch(r"C\d", name):
        return TAB10[int(name[1])]
    if name in _NAMED:
        return _NAMED[name]
    try:
        grey = float(name)
    except ValueError:
        grey = math.nan
    if not 0.0 <= grey <= 1.0:
        raise UsageError(f"a colour is C0..C9, k, white, a grey level 0..1 or #rrggbb, got {name!r}")
    level = round(255 * grey)
    return f"#{level:02x}{level:02x}{level:02x}"


#: ColorBrewer's diverging red-blue, reversed (RdBu_r): -1 dark blue, 0 near white, +1 dark red; 11 stops.
RDBU_R = ("#053061", "#2166ac", "#4393c3", "#92c5de", "#d1e5f0", "#f7f7f7", "#fddbc7", "#f4a582", "#d6604d",
          "#b2182b", "#67001f")  # fmt: skip
#: The colour of a cell without a value (a grey, 75 % white).
MISSING = "#bfbfbf"


def diverging(value: float, lo: float = -1.0, hi: float = 1.0) -> str:
    """The colour of a value on a diverging scale.

    Parameters
    ----------
    value
        The value (a correlation: -1 .. 1).
    lo, hi
        The values at the scale's blue and red ends.

    Returns
    -------
    str
        ``#rrggbb`` on :data:`RDBU_R`, interpolated linearly between its stops and clipped at its ends;
        :data:`MISSING` when ``value`` is not finite.
    """
    if not math.isfinite(value):
        return MISSING
    s = min(max((value - lo) / (hi - lo), 0.0), 1.0) * (len(RDBU_R) - 1)
    k = min(int(s), len(RDBU_R) - 2)
    a, b = RDBU_R[k], RDBU_R[k + 1]
    mix = [round(int(a[i : i + 2], 16) * (k + 1 - s) + int(b[i : i + 2], 16) * (s - k)) for i in (1, 3, 5)]
    return "#" + "".join(f"{c:02x}" for c in mix)


def luminance(hex_colour: str) -> float:
    """Perceived brightness of a colour (text on it is white below 0.5).

    Parameters
    ----------
    hex_colour
        ``#rrggbb``.

    Returns
    -------
    float
        0.299 r + 0.587 g + 0.114 b, from 0 (black) to 1 (white).
    """
    r, g, b = (int(hex_colour[i : i + 2], 16) / 255.0 for i in (1, 3, 5))
    return 0.299 * r + 0.587 * g + 0.114 * b


def num(value: float) -> str:
    """A number as SVG writes it.

    Parameters
    ----------
    value
        A coordinate or size, px.

    Returns
    -------
    str
        Rounded to 2 decimals, without trailing zeros: ``12.5``, ``3``, never ``-0``.
    """
    text = f"{round(float(value), 2) + 0.0:.2f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def escape(text: str) -> str:
    """Text made safe for XML.

    Parameters
    ----------
    text
        Any text (a robot's name, a log's path, a label).

    Returns
    -------
    str
        The text for an XML text node or a double-quoted attribute: ``&``, ``<``, ``>`` and ``"`` escaped; what
        XML 1.0 forbids (:data:`wmrid.core.xml_chars.XML_FORBIDDEN`: control characters, lone surrogates, which
        UTF-8 cannot encode either, U+FFFE and U+FFFF) and carriage returns dropped; newlines and tabs kept.
    """
    text = XML_FORBIDDEN.sub("", text).replace("\r", "")
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace('"', "&quot;")


def stroke(color: str, width: float, dash: str | None = None, opacity: float = 1.0) -> str:
    """The stroke attributes of a line.

    Parameters
    ----------
    color
        A colour name (:func:`colour`).
    width
        px.
    dash
        None (solid), ``--``, ``:`` or ``-.``: :data:`_DASHES`, scaled by the width.
    opacity
        0 .. 1.

    Returns
    -------
    str
        ``stroke="..." stroke-width="..."`` and, when needed, ``stroke-dasharray`` and ``stroke-opacity``.
    """
    out = f'stroke="{colour(color)}" stroke-width="{num(width)}"'
    if dash in _DASHES:
        out += f' stroke-dasharray="{",".join(num(d * width) for d in _DASHES[dash])}"'
    return out + (f' stroke-opacity="{num(opacity)}"' if opacity < 1.0 else "")


def points(xs: np.ndarray, ys: np.ndarray) -> str:
    """A polyline's ``points`` attribute.

    Parameters
    ----------
    xs, ys
        (n,) px each, finite.

    Returns
    -------
    str
        ``x,y x,y ...``, 2 decimals, a point that repeats the one before (after rounding) left out.
    """
    xs = np.round(np.asarray(xs, dtype=np.float64), 2) + 0.0
    ys = np.round(np.asarray(ys, dtype=np.float64), 2) + 0.0
    if len(xs) > 1:
        keep = np.ones(len(xs), dtype=bool)
        keep[1:] = (np.diff(xs) != 0) | (np.diff(ys) != 0)
        xs, ys = xs[keep], ys[keep]
    return " ".join(f"{x:.10g},{y:.10g}" for x, y in zip(xs.tolist(), ys.tolist(), strict=True))


def segments(px: np.ndarray, py: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The pieces of a line between its missing points.

    Parameters
    ----------
    px, py
        (n,) px each; NaN where a value is missing (or one a log axis cannot show).

    Returns
    -------
    list of (px, py)
        The runs of finite points, in order, each of 2 points or more (a lone point joins nothing).
    """
    ok = np.isfinite(px) & np.isfinite(py)
    if ok.all():
        return [(px, py)] if len(px) > 1 else []
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
    return [(px[a:b], py[a:b]) for a, b in zip(edges[::2], edges[1::2], strict=True) if b - a > 1]


def simplify(px: np.ndarray, py: np.ndarray, tolerance: float = 0.1) -> np.ndarray:
    """The points that draw a polyline to within a tolerance (Douglas-Peucker).

    Parameters
    ----------
    px, py
        (n,) px each, finite.
    tolerance
        px: every point left out lies within this distance of the segment drawn past it (0.1 px: invisible).

    Returns
    -------
    (m,) int
        Indices of the points kept, increasing, the ends always among them.
    """
    n = len(px)
    if n < 3:
        return np.arange(n)
    keep = np.zeros(n, dtype=bool)
    keep[[0, n - 1]] = True
    stack = [(0, n - 1)]
    while stack:
        i, j = stack.pop()
        if j - i < 2:
            continue
        dx, dy = px[j] - px[i], py[j] - py[i]
        ox, oy = px[i + 1 : j] - px[i], py[i + 1 : j] - py[i]
        length2 = dx * dx + dy * dy
        along = np.clip((ox * dx + oy * dy) / length2, 0.0, 1.0) if length2 > 0 else 0.0
        dist2 = (ox - along * dx) ** 2 + (oy - along * dy) ** 2  # to the segment: a spike back along it counts
        k = int(np.argmax(dist2))
        if dist2[k] > tolerance * tolerance:
            m = i + 1 + k
            keep[m] = True
            stack += [(i, m), (m, j)]
    return np.flatnonzero(keep)


def window(box: Window, margin: float = CLIP_MARGIN) -> Window:
    """A panel's box (left, top, right, bottom) px widened by ``margin`` px on every side."""
    left, top, right, bottom = box
    return left - margin, top - margin, right + margin, bottom + margin


def clip_line(px: np.ndarray, py: np.ndarray, win: Window) -> list[tuple[np.ndarray, np.ndarray]]:
    """The parts of a polyline within a window (Liang-Barsky, segment by segment).

    Parameters
    ----------
    px, py
        (n,) px each, finite (within ±:data:`FAR`).
    win
        (left, top, right, bottom) px.

    Returns
    -------
    list of (px, py)
        Its runs within the window, in order: the points inside kept as they are; a segment that crosses the
        window's edge cut there, the cut point on the edge exactly and, along it, computed from the segment's
        nearer end (so off by about 1e-16 of the segment's extent along the edge: 1e-13 px for a spike of 1e40 px
        from a point in the panel); a segment outside left out, the line broken there.  The visible part of every
        segment is unchanged; each run has 2 points or more, and some length.
    """
    left, top, right, bottom = win
    inside = (px >= left) & (px <= right) & (py >= top) & (py <= bottom)
    if inside.all():
        return [(px, py)] if len(px) > 1 else []
    x0, y0, x1, y1 = px[:-1], py[:-1], px[1:], py[1:]
    dx, dy = x1 - x0, y1 - y0
    t0, t1 = np.zeros(len(dx)), np.ones(len(dx))
    e0, e1 = np.full(len(dx), -1), np.full(len(dx), -1)  # the edge each end was cut at (-1: not cut)
    hidden = np.zeros(len(dx), dtype=bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        for k, (p, q) in enumerate(((-dx, x0 - left), (dx, right - x0), (-dy, y0 - top), (dy, bottom - y0))):
            ratio = q / p  # p t <= q along the segment x0 + t dx, y0 + t dy
            hidden |= (p == 0) & (q < 0)
            enter, leave = (p < 0) & (ratio > t0), (p > 0) & (ratio < t1)
            t0, e0 = np.where(enter, ratio, t0), np.where(enter, k, e0)
            t1, e1 = np.where(leave, ratio, t1), np.where(leave, k, e1)
    shown = ~hidden & (t0 <= t1)
    ends = []
    for t, e in ((t0, e0), (t1, e1)):
        near = t <= 0.5
        ex = np.where(near, x0 + t * dx, x1 - (1.0 - t) * dx)
        ey = np.where(near, y0 + t * dy, y1 - (1.0 - t) * dy)
        ex = np.where(e == 0, left, np.where(e == 1, right, np.clip(ex, left, right)))
        ey = np.where(e == 2, top, np.where(e == 3, bottom, np.clip(ey, top, bottom)))
        ends.append((ex, ey))
    (ax, ay), (bx, by) = ends
    starts = shown & ((np.arange(len(dx)) == 0) | ~inside[:-1])  # a run starts where the line enters
    emit = np.stack([starts, shown], axis=1).ravel()
    xs, ys = np.stack([ax, bx], axis=1).ravel()[emit], np.stack([ay, by], axis=1).ravel()[emit]
    run = np.cumsum(np.stack([starts, np.zeros_like(starts)], axis=1).ravel())[emit]
    cuts = np.flatnonzero(np.diff(run)) + 1
    return [
        (x, y)
        for x, y in zip(np.split(xs, cuts), np.split(ys, cuts), strict=True)
        if len(x) > 1 and (np.ptp(x) > 0 or np.ptp(y) > 0)
    ]


def clip_polygon(px: np.ndarray, py: np.ndarray, win: Window) -> tuple[np.ndarray, np.ndarray]:
    """A polygon cut to a window (Sutherland-Hodgman, one edge of the window at a time).

    Parameters
    ----------
    px, py
        (n,) px each, finite (within ±:data:`FAR`): the polygon's corners, closed implicitly.
    win
        (left, top, right, bottom) px.

    Returns
    -------
    (px, py)
        The corners of the part within the window (the cut points computed as in :func:`clip_line`; none when the
        polygon lies outside).  Inside the window every point is covered as many times as before (the fill is the
        same, whatever the fill rule); where the polygon left the window it runs along the window's edge instead.
    """
    x, y = px, py
    for axis, bound, low in ((0, win[0], True), (0, win[2], False), (1, win[1], True), (1, win[3], False)):
        c = x if axis == 0 else y
        inside = c >= bound if low else c <= bound
        if inside.all() or len(c) == 0:
            continue
        nx, ny, nc = np.roll(x, -1), np.roll(y, -1), np.roll(c, -1)
        cross = inside != np.roll(inside, -1)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(cross, (bound - c) / (nc - c), 0.0)
        near = t <= 0.5
        ix = np.where(near, x + t * (nx - x), nx - (1.0 - t) * (nx - x))
        iy = np.where(near, y + t * (ny - y), ny - (1.0 - t) * (ny - y))
        if axis == 0:
            ix = np.full_like(ix, bound)
        else:
            iy = np.full_like(iy, bound)
        emit = np.stack([inside, cross], axis=1).ravel()
        x, y = np.stack([x, ix], axis=1).ravel()[emit], np.stack([y, iy], axis=1).ravel()[emit]
    return x, y
