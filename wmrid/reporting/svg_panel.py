"""A panel of an SVG figure (:mod:`wmrid.reporting.svg`): its two axes (:class:`Axis`) and what it draws
(:class:`Panel`: lines, markers, rules, spans, bands, bars, cells, text; its title, labels and legend)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TypeVar

import numpy as np
from numpy.typing import ArrayLike

from wmrid.core.errors import UsageError
from wmrid.reporting.decimate import MAX_POINTS, decimate_for_display
from wmrid.reporting.svg_artists import (
    Artist,
    Band,
    Bars,
    Cells,
    Entry,
    Gradient,
    Line,
    Mapping,
    Markers,
    Rule,
    Span,
    Text,
)
from wmrid.reporting.svg_style import FONT, SMALL, TICK, TITLE

_A = TypeVar("_A", bound=Artist)


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

    def _add(self, artist: _A) -> _A:
        self.artists.append(artist)
        return artist

    def line(
        self, x: ArrayLike, y: ArrayLike, *, color: str = "C0", width: float = 1.5, dash: str | None = None,
        opacity: float = 1.0, label: str | None = None, decimate: bool = True,
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
        self, x: ArrayLike, y: ArrayLike, *, shape: str = "o", color: str = "C0", size: float = 8.0, clip: bool = True,
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

    def band(self, x: ArrayLike, lo: ArrayLike, hi: ArrayLike, *, color: str = "C0", opacity: float = 0.25,
             label: str | None = None) -> Band:  # fmt: skip
        """The area between ``lo`` and ``hi`` over ``x`` (n,) each; NaN breaks it."""
        xs, los, his = (np.asarray(a, dtype=np.float64).ravel() for a in (x, lo, hi))
        return self._add(Band(xs, los, his, color, opacity, label=label))

    def bars(
        self, positions: ArrayLike, values: ArrayLike, *, width: float = 0.8, colors: Sequence[str] | str = "C0",
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
