"""wmrid's own plotting layer: figures drawn straight to SVG, with numpy and the standard library only.

A :class:`Figure` has a fixed size (inches at :data:`PX_PER_INCH`; a ``viewBox`` lets it scale to the page's width)
and panels on a grid at fixed margins (or at given boxes).  A :class:`Panel` draws lines (NaN breaks them; long
series reduced by :func:`wmrid.reporting.decimate.decimate_for_display`, so no line has more than
:data:`~wmrid.reporting.decimate.MAX_POINTS` points), markers, horizontal and vertical lines, spans, bands, bars,
cells and text (:mod:`wmrid.reporting.svg_artists`) on linear, log10 or date axes with nice ticks
(:mod:`wmrid.reporting.svg_axes`), clipped to its box; a legend sits in a corner of a panel or in rows below the
panels.  Text stays text (``<text>``, sans-serif), escaped.  The same figure gives the same bytes: no date, no
random id (ids are derived from the content, so several figures in one page never share one).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from wmrid.core.errors import UsageError
from wmrid.reporting.decimate import MAX_POINTS, decimate_for_display
from wmrid.reporting.svg_artists import (
    FONT,
    ID_PLACEHOLDER,
    SMALL,
    TICK,
    TITLE,
    Artist,
    Band,
    Bars,
    Cells,
    Gradient,
    Line,
    Mapping,
    Markers,
    Rule,
    Span,
    Text,
    num,
)
from wmrid.reporting.svg_draw import Entry, draw_figure

__all__ = ["FONT", "PX_PER_INCH", "SMALL", "TITLE", "Axis", "Entry", "Figure", "Panel"]

#: px per inch of a figure's size (the CSS px).
PX_PER_INCH = 96.0


class Axis:
    """One axis of a panel: scale ("linear", "log", "date": days since 0001-01-01), limits (None: from the data),
    label, explicit ticks, whether its tick labels show, and their font size (px)."""

    def __init__(self) -> None:
        self.scale = "linear"
        self.lim: tuple[float, float] | None = None
        self.label = ""
        self.label_size = FONT
        self.ticks: tuple[list[float], list[str]] | None = None
        self.labels_visible = True
        self.size = FONT
        self.tick_length = TICK
        self.side = ""  # a y axis' ticks on the "left" ("") or the "right"

    def mapping(self, lo: float, hi: float, p0: float, p1: float) -> Mapping:
        """Data (n,) -> px (n,) from ``lo``..``hi`` onto ``p0``..``p1`` (NaN: values a log axis cannot show)."""
        if self.scale == "log":
            a, b = math.log10(lo), math.log10(hi)

            def log_px(v: np.ndarray) -> np.ndarray:
                v = np.asarray(v, dtype=np.float64)
                with np.errstate(all="ignore"):
                    return p0 + (np.log10(np.where(v > 0, v, np.nan)) - a) / (b - a) * (p1 - p0)

            return log_px
        return lambda v: p0 + (np.asarray(v, dtype=np.float64) - lo) / (hi - lo) * (p1 - p0)


class Panel:
    """One plotting area of a figure, at ``box`` (left, top, width, height) px; ``cell`` its (row, column) on the
    figure's grid.  Methods add what it draws; data in the axes' units, sizes and widths in px."""

    def __init__(self, box: tuple[float, float, float, float], cell: tuple[int, int] | None = None) -> None:
        self.box = box
        self.cell = cell
        self.artists: list[Artist] = []
        self.x, self.y = Axis(), Axis()
        self.title, self.title_size, self.title_color = "", TITLE, "k"
        self.grid = ""  # "", "x", "y" or "xy"
        self.equal = False
        self.frame = True
        self.legend_loc: str | None = None
        self.legend_size = SMALL
        self.legend_texts: list[str] = []
        self.hidden = False

    def _add(self, artist: Artist) -> Any:
        self.artists.append(artist)
        return artist

    def line(
        self, x: Any, y: Any, *, color: str = "C0", width: float = 1.5, dash: str | None = None, opacity: float = 1.0,
        label: str | None = None, decimate: bool = True,
    ) -> Line:  # fmt: skip
        """A line through (x, y) (n,) each; NaN breaks it.  ``decimate``: a series in the order of x reduced for
        display to 4 points per px of the panel's width (at most MAX_POINTS), every bin's extremes kept, so the drawn
        envelope is the data's; a line is never drawn with more than MAX_POINTS points."""
        x, y = np.asarray(x, dtype=np.float64).ravel(), np.asarray(y, dtype=np.float64).ravel()
        if x.shape != y.shape:
            raise UsageError(f"a line needs x and y of one length, got {x.shape} and {y.shape}")
        if decimate:
            x, y = decimate_for_display(x, y, min(MAX_POINTS, max(200, int(4 * self.box[2]))))
        elif len(x) > MAX_POINTS:
            x, y = decimate_for_display(x, y)
        return self._add(Line(x, y, color, width, dash, opacity, label=label))

    def markers(
        self, x: Any, y: Any, *, shape: str = "o", color: str = "C0", size: float = 8.0, clip: bool = True,
        label: str | None = None,
    ) -> Markers:  # fmt: skip
        """A marker (``o``, ``.``, ``s``, ``^``, ``v``, ``x``; ``size`` px) at each (x, y) (n,); ``clip`` False: shown
        on the panel's edge too."""
        x, y = np.atleast_1d(np.asarray(x, dtype=np.float64)), np.atleast_1d(np.asarray(y, dtype=np.float64))
        return self._add(Markers(x, y, shape, color, size, clip, label=label))

    def hline(self, y: float, *, color: str = "k", width: float = 1.0, dash: str | None = None,
              label: str | None = None) -> Rule:  # fmt: skip
        """A horizontal line across the panel at ``y``."""
        return self._add(Rule(float(y), "y", color, width, dash, label=label))

    def vline(self, x: float, *, color: str = "k", width: float = 1.0, dash: str | None = None,
              label: str | None = None) -> Rule:  # fmt: skip
        """A vertical line across the panel at ``x``."""
        return self._add(Rule(float(x), "x", color, width, dash, label=label))

    def hspan(self, lo: float, hi: float, *, color: str = "C3", opacity: float = 0.2, label: str | None = None) -> Span:
        """A band across the panel from y = ``lo`` to ``hi``."""
        return self._add(Span(float(lo), float(hi), color, opacity, label=label))

    def band(self, x: Any, lo: Any, hi: Any, *, color: str = "C0", opacity: float = 0.25,
             label: str | None = None) -> Band:  # fmt: skip
        """The area between ``lo`` and ``hi`` over ``x`` (n,) each; NaN breaks it."""
        arrays = [np.asarray(a, dtype=np.float64).ravel() for a in (x, lo, hi)]
        return self._add(Band(*arrays, color, opacity, label=label))

    def bars(
        self, positions: Any, values: Any, *, width: float = 0.8, colors: Sequence[str] | str = "C0",
        horizontal: bool = False, label: str | None = None,
    ) -> Bars:  # fmt: skip
        """Bars of ``values`` (n,) at ``positions`` (n,), ``width`` data units wide (NaN: no bar); ``colors`` one
        for all or one per bar; ``horizontal``: the values along x."""
        colors = (colors,) if isinstance(colors, str) else tuple(colors)
        pos, val = np.asarray(positions, dtype=np.float64), np.asarray(values, dtype=np.float64)
        return self._add(Bars(pos, val, float(width), colors, horizontal, label=label))

    def cells(self, fills: list[list[str]]) -> Cells:
        """Unit cells coloured ``fills`` (rows, columns), cell (i, j) centred on x = j, y = i."""
        return self._add(Cells(fills))

    def gradient(self, stops: Sequence[tuple[float, str]]) -> Gradient:
        """The panel filled with a colour scale from its bottom (offset 0) to its top (1)."""
        return self._add(Gradient(tuple(stops)))

    def text(self, x: float, y: float, text: str, *, color: str = "k", size: float = FONT,
             anchor: str = "middle") -> Text:  # fmt: skip
        """``text`` centred vertically on (x, y) (data units)."""
        return self._add(Text(float(x), float(y), text, color, size, anchor))

    def set_title(self, text: str, *, size: float = TITLE, color: str = "k") -> None:
        """The title above the panel (lines split at ``\\n``)."""
        self.title, self.title_size, self.title_color = text, size, color

    def set_xlabel(self, text: str, *, size: float = FONT) -> None:
        self.x.label, self.x.label_size = text, size

    def set_ylabel(self, text: str, *, size: float = FONT) -> None:
        self.y.label, self.y.label_size = text, size

    def set_xlim(self, lo: float, hi: float) -> None:
        self.x.lim = (float(lo), float(hi))

    def set_ylim(self, lo: float, hi: float) -> None:
        self.y.lim = (float(lo), float(hi))

    def legend(self, loc: str = "best", *, size: float = SMALL, texts: Sequence[str] = ()) -> None:
        """A legend of the labelled artists in a corner: ``loc`` "best" (the corner over the fewest drawn points),
        "upper right", "upper left", "lower left" or "lower right"; ``texts``: entries that are text only."""
        self.legend_loc, self.legend_size, self.legend_texts = loc, size, list(texts)

    def entries(self) -> list[Entry]:
        """The legend entries of its labelled artists (first of each label), in order, then its text entries."""
        out: dict[str, Entry] = {}
        for a in self.artists:
            if a.label and a.label not in out:
                kind, style = a.handle()
                out[a.label] = (kind, style, a.label)
        return [*out.values(), *[("text", {}, t) for t in self.legend_texts]]


class Figure:
    """A figure of ``size`` (width, height) inches with panels on a ``grid`` (rows, columns) at fixed margins,
    inches: ``left`` (tick labels and the y label), ``right``, ``top`` (titles), ``bottom`` (the x label, and a legend
    row below it), ``gaps`` (between columns, between rows); ``width_ratios`` of the columns; ``sharex`` /
    ``sharey``: every panel has the same x (y) limits, and only the panels at the bottom of their column (at the left
    of their row) label those ticks.  ``panels``: row by row; :meth:`add_panel` places one at a box of its own.
    """

    def __init__(
        self, size: tuple[float, float], *, grid: tuple[int, int] = (1, 1), left: float = 0.8, right: float = 0.2,
        top: float = 0.15, bottom: float = 0.55, gaps: tuple[float, float] = (0.0, 0.0),
        width_ratios: Sequence[float] | None = None, sharex: bool = False, sharey: bool = False,
    ) -> None:  # fmt: skip
        self.width, self.height = size[0] * PX_PER_INCH, size[1] * PX_PER_INCH
        self.sharex, self.sharey = sharex, sharey
        self.below: list[Entry] = []
        rows, cols = grid
        ratios = np.asarray(width_ratios if width_ratios is not None else [1.0] * cols, dtype=np.float64)
        inner_w = self.width - (left + right + (cols - 1) * gaps[0]) * PX_PER_INCH
        panel_h = (self.height - (top + bottom + (rows - 1) * gaps[1]) * PX_PER_INCH) / rows
        widths = inner_w * ratios / ratios.sum()
        self.panels: list[Panel] = []
        for r in range(rows):
            for c in range(cols):
                x = (left + c * gaps[0]) * PX_PER_INCH + float(widths[:c].sum())
                y = (top + r * gaps[1]) * PX_PER_INCH + r * panel_h
                self.panels.append(Panel((x, y, float(widths[c]), panel_h), (r, c)))

    @property
    def size(self) -> tuple[float, float]:
        """(width, height) px."""
        return self.width, self.height

    def add_panel(self, box: tuple[float, float, float, float]) -> Panel:
        """A panel at ``box`` (left, top, width, height) px, outside the grid."""
        panel = Panel(box)
        self.panels.append(panel)
        return panel

    def remove(self, panel: Panel) -> None:
        """Leave ``panel`` out (an unused cell of the grid)."""
        panel.hidden = True

    @property
    def visible(self) -> list[Panel]:
        return [p for p in self.panels if not p.hidden]

    def legend_below(self, entries: Sequence[Entry]) -> None:
        """A legend in rows along the bottom edge (the ``bottom`` margin keeps room for one row; more rows make the
        figure taller)."""
        self.below = list(entries)

    def entries(self, panels: Sequence[Panel] | None = None) -> list[Entry]:
        """The legend entries of ``panels`` (default: every panel shown), the first of each label, in order."""
        out: dict[str, Entry] = {}
        for p in self.visible if panels is None else panels:
            for e in p.entries():
                out.setdefault(e[2], e)
        return list(out.values())

    def to_svg(self) -> bytes:
        """The figure as a standalone SVG document (UTF-8 bytes): the same figure, the same bytes."""
        body, height = draw_figure(self)
        digest = hashlib.sha256(body.encode("utf-8")).hexdigest()[:10]
        body = body.replace(ID_PLACEHOLDER, f"w{digest}-")
        w, h = num(self.width), num(height)
        return (
            '<?xml version="1.0" encoding="utf-8"?>\n'
            f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" '
            f'font-family="sans-serif" stroke-linejoin="round">\n'
            f'<rect width="{w}" height="{h}" fill="#ffffff"/>\n{body}</svg>\n'
        ).encode()
