"""What a panel of an SVG figure (:mod:`wmrid.reporting.svg`) draws: lines, markers, horizontal and vertical lines,
spans, bands, bars, cells and text, each turned into SVG elements by the panel's coordinate mapping.

Every number written is rounded to 2 decimals (px), so files stay small and the same data give the same bytes.
What lies beyond a panel's box is cut at :data:`~wmrid.reporting.svg_style.CLIP_MARGIN` px from it (the panel clips at
its box): a value far out (1e40, 1e300) draws the line, band, span or bar up to there, as a browser could not.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wmrid.reporting.svg_style import (
    CLIP_MARGIN,
    FONT,
    Window,
    clip_line,
    clip_polygon,
    colour,
    escape,
    num,
    points,
    segments,
    simplify,
    stroke,
    window,
)

#: Draw order: patches (spans, bands, bars, cells) under lines and markers, text on top.
Z_PATCH, Z_LINE, Z_TEXT = 1, 2, 3

#: A legend entry: (kind, style, label) as :meth:`Artist.handle` gives them, with the label.
Entry = tuple[str, dict[str, Any], str]
#: A mapping of data values (n,) to px (n,) along one axis (NaN where a value cannot be drawn: <= 0 on a log axis).
Mapping = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Frame:
    """A panel's mapping from data to px: ``fx``, ``fy``, its box in px (left, top, right, bottom), and the prefix
    of the ids its elements may define (unique in the page)."""

    fx: Mapping
    fy: Mapping
    box: tuple[float, float, float, float]
    ident: str = ""


@dataclass
class Artist(ABC):
    """Something a panel draws (each kind defines :meth:`draw`); ``label`` puts it in a legend (None: not listed)."""

    label: str | None = field(default=None, kw_only=True)
    zorder: int = field(default=Z_LINE, kw_only=True)

    def extent(self) -> tuple[np.ndarray, np.ndarray]:
        """Its data values along x and along y (for the axes' automatic limits; empty when it has none)."""
        return np.array([]), np.array([])

    @abstractmethod
    def draw(self, frame: Frame) -> str:
        """Its SVG elements in ``frame``."""

    def handle(self) -> tuple[str, dict[str, Any]]:
        """What its legend entry shows: ("line", style), ("patch", style), ("marker", style) or ("text", {})."""
        return "text", {}


@dataclass
class Line(Artist):
    """A polyline through (x, y) (n,); NaN breaks it."""

    x: np.ndarray
    y: np.ndarray
    color: str = "C0"
    width: float = 1.5
    dash: str | None = None
    opacity: float = 1.0

    def extent(self) -> tuple[np.ndarray, np.ndarray]:
        return self.x, self.y

    def draw(self, frame: Frame) -> str:
        style = f'fill="none" {stroke(self.color, self.width, self.dash, self.opacity)}'
        out = []
        win = window(frame.box)
        for sx, sy in (run for piece in segments(frame.fx(self.x), frame.fy(self.y)) for run in clip_line(*piece, win)):
            kept = simplify(sx, sy)
            out.append(f'<polyline points="{points(sx[kept], sy[kept])}" {style}/>')
        return "".join(out)

    def handle(self) -> tuple[str, dict[str, Any]]:
        return "line", {"color": self.color, "width": self.width, "dash": self.dash, "opacity": self.opacity}


def marker_path(shape: str, xs: Sequence[float], ys: Sequence[float], size: float) -> str:
    """One path drawing a marker at every point.

    Parameters
    ----------
    shape
        ``o`` circle, ``.`` dot, ``s`` square, ``^``/``v`` triangle, ``x`` cross.
    xs, ys
        (n,) px each.
    size
        The marker's size across, px.

    Returns
    -------
    str
        The path's ``d`` (a cross is stroked, the others filled).
    """
    r = size / 2.0
    out = []
    for x, y in zip(xs, ys, strict=True):
        if shape in ("o", "."):
            out.append(f"M{num(x - r)},{num(y)}a{num(r)},{num(r)} 0 1,0 {num(2 * r)},0a{num(r)},{num(r)} 0 1,0 "
                       f"{num(-2 * r)},0z")  # fmt: skip
        elif shape == "s":
            out.append(f"M{num(x - r)},{num(y - r)}h{num(2 * r)}v{num(2 * r)}h{num(-2 * r)}z")
        elif shape in ("^", "v"):
            tip = -r if shape == "^" else r
            out.append(f"M{num(x)},{num(y + tip)}L{num(x + r)},{num(y - tip)}H{num(x - r)}z")
        else:  # "x"
            out.append(f"M{num(x - r)},{num(y - r)}L{num(x + r)},{num(y + r)}M{num(x - r)},{num(y + r)}"
                       f"L{num(x + r)},{num(y - r)}")  # fmt: skip
    return "".join(out)


@dataclass
class Markers(Artist):
    """A marker at each (x, y) (n,); ``size`` px across; ``clip``: False lets them show on the panel's edge."""

    x: np.ndarray
    y: np.ndarray
    shape: str = "o"
    color: str = "C0"
    size: float = 8.0
    clip: bool = True

    def extent(self) -> tuple[np.ndarray, np.ndarray]:
        return self.x, self.y

    def draw(self, frame: Frame) -> str:
        px, py = frame.fx(self.x), frame.fy(self.y)
        left, top, right, bottom = window(frame.box, CLIP_MARGIN + self.size)
        ok = (px >= left) & (px <= right) & (py >= top) & (py <= bottom)  # (NaN: False)
        if not ok.any():
            return ""
        d = marker_path(self.shape, px[ok].tolist(), py[ok].tolist(), self.size)
        paint = f'fill="none" {stroke(self.color, 1.3)}' if self.shape == "x" else f'fill="{colour(self.color)}"'
        return f'<path d="{d}" {paint}/>'

    def handle(self) -> tuple[str, dict[str, Any]]:
        return "marker", {"shape": self.shape, "color": self.color, "size": min(self.size, 9.0)}


@dataclass
class Rule(Artist):
    """A horizontal (``axis`` "y": at y = value) or vertical (``axis`` "x") line across the panel."""

    value: float
    axis: str = "y"
    color: str = "k"
    width: float = 1.0
    dash: str | None = None

    def extent(self) -> tuple[np.ndarray, np.ndarray]:
        v = np.array([self.value], dtype=np.float64)
        return (v, np.array([])) if self.axis == "x" else (np.array([]), v)

    def draw(self, frame: Frame) -> str:
        left, top, right, bottom = frame.box
        style = stroke(self.color, self.width, self.dash)
        if self.axis == "y":
            y = float(frame.fy(np.array([self.value]))[0])
            return f'<path d="M{num(left)},{num(y)}H{num(right)}" {style}/>' if _within(y, top, bottom) else ""
        x = float(frame.fx(np.array([self.value]))[0])
        return f'<path d="M{num(x)},{num(top)}V{num(bottom)}" {style}/>' if _within(x, left, right) else ""

    def handle(self) -> tuple[str, dict[str, Any]]:
        return "line", {"color": self.color, "width": self.width, "dash": self.dash, "opacity": 1.0}


@dataclass
class Span(Artist):
    """A band across the panel from y = lo to y = hi."""

    lo: float
    hi: float
    color: str = "C3"
    opacity: float = 0.2
    zorder: int = field(default=Z_PATCH, kw_only=True)

    def extent(self) -> tuple[np.ndarray, np.ndarray]:
        return np.array([]), np.array([self.lo, self.hi], dtype=np.float64)

    def draw(self, frame: Frame) -> str:
        left, _, right, _ = frame.box
        y0, y1 = frame.fy(np.array([self.lo, self.hi], dtype=np.float64))
        if not (math.isfinite(y0) and math.isfinite(y1)):
            return ""
        return rect(left, right, y0, y1, window(frame.box), f'fill="{colour(self.color)}" '
                    f'fill-opacity="{num(self.opacity)}"')  # fmt: skip

    def handle(self) -> tuple[str, dict[str, Any]]:
        return "patch", {"color": self.color, "opacity": self.opacity}


#: The width (px) of a band at a lone point (a single sample, or one between missing ones): a narrow bar.
LONE_WIDTH = 6.0


@dataclass
class Band(Artist):
    """The area between lo (n,) and hi (n,) over x (n,); NaN breaks it; at a lone point, a bar :data:`LONE_WIDTH` px
    wide from lo to hi."""

    x: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    color: str = "C0"
    opacity: float = 0.25
    zorder: int = field(default=Z_PATCH, kw_only=True)

    def extent(self) -> tuple[np.ndarray, np.ndarray]:
        return self.x, np.concatenate([self.lo, self.hi])

    def draw(self, frame: Frame) -> str:
        px, plo, phi = frame.fx(self.x), frame.fy(self.lo), frame.fy(self.hi)
        ok = (np.isfinite(px) & np.isfinite(plo) & np.isfinite(phi)).astype(np.int8)
        edges = np.flatnonzero(np.diff(np.concatenate([[0], ok, [0]])))
        out = []
        win = window(frame.box)
        paint = f'fill="{colour(self.color)}" fill-opacity="{num(self.opacity)}"'
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            if b - a < 2:  # a lone point: no area between points, a narrow bar
                x = float(px[a])
                out.append(rect(x - LONE_WIDTH / 2, x + LONE_WIDTH / 2, float(plo[a]), float(phi[a]), win, paint))
                continue
            xs = np.concatenate([px[a:b], px[a:b][::-1]])
            ys = np.concatenate([phi[a:b], plo[a:b][::-1]])
            xs, ys = clip_polygon(xs, ys, win)
            if len(xs) < 3:
                continue
            out.append(f'<polygon points="{points(xs, ys)}" {paint}/>')
        return "".join(out)

    def handle(self) -> tuple[str, dict[str, Any]]:
        return "patch", {"color": self.color, "opacity": self.opacity}


@dataclass
class Bars(Artist):
    """Bars at positions (n,) with values (n,), ``width`` in data units, from 0 (from the axis' edge on a log
    axis); ``horizontal``: the values run along x.  NaN: no bar."""

    positions: np.ndarray
    values: np.ndarray
    width: float = 0.8
    colors: tuple[str, ...] = ("C0",)
    horizontal: bool = False
    zorder: int = field(default=Z_PATCH, kw_only=True)

    def extent(self) -> tuple[np.ndarray, np.ndarray]:
        along = np.concatenate([self.positions - self.width / 2, self.positions + self.width / 2])
        return (self.values, along) if self.horizontal else (along, self.values)

    def draw(self, frame: Frame) -> str:
        left, _, _, bottom = frame.box
        f_along, f_value = (frame.fy, frame.fx) if self.horizontal else (frame.fx, frame.fy)
        a0 = f_along(self.positions - self.width / 2)
        a1 = f_along(self.positions + self.width / 2)
        v = f_value(self.values)
        base = float(f_value(np.array([0.0]))[0])
        if not math.isfinite(base):  # a log axis: from its edge
            base = left if self.horizontal else bottom
        out = []
        win = window(frame.box)
        for k in range(len(v)):
            if not (math.isfinite(v[k]) and math.isfinite(a0[k]) and math.isfinite(a1[k])):
                continue
            value, along = (base, float(v[k])), (float(a0[k]), float(a1[k]))
            (x0, x1), (y0, y1) = (value, along) if self.horizontal else (along, value)
            out.append(rect(x0, x1, y0, y1, win, f'fill="{colour(self.colors[k % len(self.colors)])}"'))
        return "".join(out)

    def handle(self) -> tuple[str, dict[str, Any]]:
        return "patch", {"color": self.colors[0], "opacity": 1.0}


@dataclass
class Cells(Artist):
    """A grid of unit cells centred on (column j, row i) of ``fills`` (rows, columns) colours, with thin white
    gaps between them."""

    fills: list[list[str]]
    zorder: int = field(default=Z_PATCH, kw_only=True)

    def extent(self) -> tuple[np.ndarray, np.ndarray]:
        rows, cols = len(self.fills), len(self.fills[0]) if self.fills else 0
        return np.array([-0.5, cols - 0.5]), np.array([-0.5, rows - 0.5])

    def draw(self, frame: Frame) -> str:
        out = []
        for i, row in enumerate(self.fills):
            y0, y1 = frame.fy(np.array([i - 0.5, i + 0.5]))
            for j, fill in enumerate(row):
                x0, x1 = frame.fx(np.array([j - 0.5, j + 0.5]))
                out.append(rect(x0, x1, y0, y1, window(frame.box), f'fill="{colour(fill)}"'))
        return f'<g stroke="#ffffff" stroke-width="0.5">{"".join(out)}</g>'


@dataclass
class Gradient(Artist):
    """The panel filled with a colour scale running from its bottom to its top: ``stops`` (offset 0..1, colour)."""

    stops: tuple[tuple[float, str], ...]
    zorder: int = field(default=Z_PATCH, kw_only=True)

    def draw(self, frame: Frame) -> str:
        left, top, right, bottom = frame.box
        ident = f"{frame.ident}g"
        stops = "".join(f'<stop offset="{num(o)}" stop-color="{colour(c)}"/>' for o, c in self.stops)
        return (f'<defs><linearGradient id="{ident}" x1="0" y1="1" x2="0" y2="0">{stops}</linearGradient></defs>'
                f'<rect x="{num(left)}" y="{num(top)}" width="{num(right - left)}" height="{num(bottom - top)}" '
                f'fill="url(#{ident})"/>')  # fmt: skip


@dataclass
class Text(Artist):
    """Text at (x, y) in data units, centred on it (``anchor`` "start"/"middle"/"end" horizontally)."""

    x: float
    y: float
    text: str
    color: str = "k"
    size: float = FONT
    anchor: str = "middle"
    zorder: int = field(default=Z_TEXT, kw_only=True)

    def draw(self, frame: Frame) -> str:
        x = float(frame.fx(np.array([self.x]))[0])
        y = float(frame.fy(np.array([self.y]))[0])
        left, top, right, bottom = window(frame.box)
        if not (_within(x, left, right) and _within(y, top, bottom)):
            return ""
        return text_element(x, y, self.text, self.size, anchor=self.anchor, valign="center", color=self.color)


def _within(v: float, lo: float, hi: float) -> bool:
    """``v`` between ``lo`` and ``hi`` (a line at v shows in the panel; False for NaN)."""
    return lo <= v <= hi


def rect(x0: float, x1: float, y0: float, y1: float, win: Window, paint: str) -> str:
    """A ``<rect>`` from x0 to x1 and y0 to y1 px (either order), cut to ``win`` (so no coordinate is far out: a
    rectangle stays one when cut), with ``paint`` (its fill attributes)."""
    left, top, right, bottom = win
    xa, xb = (min(max(v, left), right) for v in sorted((x0, x1)))
    ya, yb = (min(max(v, top), bottom) for v in sorted((y0, y1)))
    return f'<rect x="{num(xa)}" y="{num(ya)}" width="{num(xb - xa)}" height="{num(yb - ya)}" {paint}/>'


def text_element(
    x: float,
    y: float,
    text: str,
    size: float,
    *,
    anchor: str = "middle",
    valign: str = "baseline",
    color: str = "k",
    rotate: bool = False,
    weight: str | None = None,
) -> str:
    """A ``<text>`` element, escaped.

    Parameters
    ----------
    x, y
        Where it stands, px.
    text
        Its text; lines split at ``\\n`` (``<tspan>`` each).
    size
        Font size, px.
    anchor
        "start", "middle" or "end" at x.
    valign
        y is the "baseline" of the last line, the "center" of the block, or the "top" of the first line.
    color, weight
        Fill colour (:func:`~wmrid.reporting.svg_style.colour`) and font weight (None: normal).
    rotate
        Read upwards (a y label), turned about (x, y).

    Returns
    -------
    str
        The element.
    """
    lines = text.split("\n")
    step = 1.2 * size
    if valign == "center":
        first = y + 0.35 * size - (len(lines) - 1) * step / 2
    elif valign == "top":
        first = y + 0.8 * size
    else:
        first = y - (len(lines) - 1) * step
    attrs = f'font-size="{num(size)}"' + ("" if anchor == "start" else f' text-anchor="{anchor}"')
    attrs += "" if colour(color) == "#000000" else f' fill="{colour(color)}"'
    attrs += f' font-weight="{weight}"' if weight else ""
    if rotate:
        attrs += f' transform="rotate(-90 {num(x)} {num(y)})"'  # about (x, y): laid out as if unrotated
    if len(lines) == 1:
        return f'<text x="{num(x)}" y="{num(first)}" {attrs}>{escape(text)}</text>'
    spans = "".join(
        f'<tspan x="{num(x)}" y="{num(first + k * step)}">{escape(line)}</tspan>' for k, line in enumerate(lines)
    )
    return f"<text {attrs}>{spans}</text>"


def legend_handle(kind: str, style: dict[str, Any], x: float, y: float, length: float = 24.0) -> str:
    """The sample a legend shows for an entry.

    Parameters
    ----------
    kind, style
        As :meth:`Artist.handle` gives them ("line", "patch", "marker"; "text": nothing).
    x, y
        Its left end and middle, px.
    length
        Its length, px.

    Returns
    -------
    str
        The element ("" for a text entry).
    """
    if kind == "line":
        dash = style.get("dash")
        return (f'<path d="M{num(x)},{num(y)}h{num(length)}" fill="none" '
                f'{stroke(style["color"], max(style["width"], 1.2), dash, style.get("opacity", 1.0))}/>')  # fmt: skip
    if kind == "patch":
        opacity = style.get("opacity", 1.0)
        fill = f'fill="{colour(style["color"])}"' + (f' fill-opacity="{num(opacity)}"' if opacity < 1.0 else "")
        return f'<rect x="{num(x)}" y="{num(y - 5)}" width="{num(length)}" height="10" {fill}/>'
    if kind == "marker":
        shape = style["shape"]
        d = marker_path(shape, [x + length / 2], [y], style["size"])
        paint = f'fill="none" {stroke(style["color"], 1.3)}' if shape == "x" else f'fill="{colour(style["color"])}"'
        return f'<path d="{d}" {paint}/>'
    return ""
