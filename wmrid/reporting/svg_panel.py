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
from wmrid.reporting.svg_style import FAR, FONT, SMALL, TICK, TITLE

_A = TypeVar("_A", bound=Artist)


class Axis:
    """One axis of a panel.

    Attributes
    ----------
    scale
        "linear", "log" (log10; values <= 0 are not drawn) or "date" (values are days since 0001-01-01,
        :func:`wmrid.reporting.svg_axes.date_number`).
    lim
        (lo, hi) in its units, or None: from the data.
    label, label_size
        Its label and the label's font size, px.
    ticks
        (positions, labels) to use instead of computed ones (categories), or None.
    labels_visible, size, tick_length
        Whether its tick labels show, their font size and the ticks' length, px.
    side
        A y axis' ticks on the left ("") or the "right" (a colour bar).
    integer
        A linear axis of counts (logs in order): ticks on whole numbers only.
    """

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
        self.integer = False

    def mapping(self, lo: float, hi: float, p0: float, p1: float) -> Mapping:
        """The mapping from the axis' units to px.

        Parameters
        ----------
        lo, hi
            Its limits (positive on a log axis).
        p0, p1
            The px they map to.

        Returns
        -------
        Mapping
            values (n,) -> px (n,), linear in the value (in its log10 on a log axis), for any finite limits: NaN for
            values that are not finite (and <= 0 on a log axis); px beyond ±:data:`~wmrid.reporting.svg_style.FAR`
            (a value 10^290 spans past the limits) held there, so that no px overflows.
        """
        log = self.scale == "log"
        if log:
            lo, hi = math.log10(lo), math.log10(hi)
        halves = not math.isfinite(hi - lo)  # limits ±1e308 apart: in halves, which cannot overflow

        def to_px(values: np.ndarray) -> np.ndarray:
            v = np.asarray(values, dtype=np.float64)
            with np.errstate(all="ignore"):
                if log:
                    v = np.log10(np.where(v > 0, v, np.nan))
                share = (v / 2 - lo / 2) / (hi / 2 - lo / 2) if halves else (v - lo) / (hi - lo)
                px = p0 + share * (p1 - p0)
                return np.where(np.isfinite(v), np.clip(px, -FAR, FAR), np.nan)

        return to_px


class Panel:
    """One plotting area of a figure: what it draws (its artists, in the axes' units), its two axes, title, grid
    and legend.  Sizes and widths are px; colours are names as :func:`wmrid.reporting.svg_style.colour` reads them
    (``C0`` .. ``C9``, ``k``, a grey level ``"0.45"``, ``#rrggbb``); ``label`` puts an artist in the legend.

    Parameters
    ----------
    box
        (left, top, width, height) px in the figure.
    cell
        Its (row, column) on the figure's grid; None for a panel placed at a box of its own.
    """

    def __init__(self, box: tuple[float, float, float, float], cell: tuple[int, int] | None = None) -> None:
        self.box = box
        self.cell = cell
        self.artists: list[Artist] = []
        self.x, self.y = Axis(), Axis()
        self.title, self.title_size, self.title_color = "", TITLE, "k"
        self.grid = ""  # "", "x", "y" or "xy": light lines at the major ticks
        self.equal = False  # a unit of x as long as a unit of y (the limits widened)
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
        """A line through the points (x, y); a NaN breaks it.

        Parameters
        ----------
        x, y
            (n,) each, in the axes' units.
        color, width, opacity
            Stroke colour, width (px) and opacity (0..1).
        dash
            None (solid), "--" (dashed), ":" (dotted) or "-." (dash-dot).
        label
            Its legend entry (None: not listed).
        decimate
            A series in the order of x, reduced for display to 4 points per px of the panel's width (at most
            MAX_POINTS), every bin's minimum and maximum kept (:func:`wmrid.reporting.decimate.decimate_for_display`),
            so the drawn envelope is the data's.  Never more than MAX_POINTS points are kept, whatever this says.

        Returns
        -------
        Line
            The artist added (its x and y as kept).
        """
        x, y = np.asarray(x, dtype=np.float64).ravel(), np.asarray(y, dtype=np.float64).ravel()
        if x.shape != y.shape:
            raise UsageError(f"a line needs x and y of one length, got {x.shape} and {y.shape}")
        _check_dash(dash)
        if decimate:
            x, y = decimate_for_display(x, y, min(MAX_POINTS, max(200, int(4 * self.box[2]))))
        elif len(x) > MAX_POINTS:
            x, y = decimate_for_display(x, y)
        return self._add(Line(x, y, color, width, dash, opacity, label=label))

    def markers(
        self, x: ArrayLike, y: ArrayLike, *, shape: str = "o", color: str = "C0", size: float = 8.0, clip: bool = True,
        label: str | None = None,
    ) -> Markers:  # fmt: skip
        """A marker at each point (x, y).

        Parameters
        ----------
        x, y
            (n,) each (or scalars), in the axes' units.
        shape
            "o" circle, "." dot, "s" square, "^" / "v" triangle, "x" cross.
        color, size
            Fill (a cross: stroke) colour, and the marker's size across, px.
        clip
            False: shown beyond the panel's edge too (markers placed on the edge).
        label
            Its legend entry (None: not listed).

        Returns
        -------
        Markers
            The artist added.
        """
        if shape not in _SHAPES:
            raise UsageError(f"a marker's shape is one of {', '.join(_SHAPES)}, got {shape!r}")
        x, y = np.atleast_1d(np.asarray(x, dtype=np.float64)), np.atleast_1d(np.asarray(y, dtype=np.float64))
        return self._add(Markers(x, y, shape, color, size, clip, label=label))

    def hline(self, y: float, *, color: str = "k", width: float = 1.0, dash: str | None = None,
              label: str | None = None) -> Rule:  # fmt: skip
        """A horizontal line across the panel at ``y`` (counts in the automatic y limits); the other parameters as
        :meth:`line`'s.  Returns the artist added."""
        _check_dash(dash)
        return self._add(Rule(float(y), "y", color, width, dash, label=label))

    def vline(self, x: float, *, color: str = "k", width: float = 1.0, dash: str | None = None,
              label: str | None = None) -> Rule:  # fmt: skip
        """A vertical line across the panel at ``x``; the other parameters as :meth:`line`'s.  Returns the artist
        added."""
        _check_dash(dash)
        return self._add(Rule(float(x), "x", color, width, dash, label=label))

    def hspan(self, lo: float, hi: float, *, color: str = "C3", opacity: float = 0.2, label: str | None = None) -> Span:
        """A band across the panel from y = ``lo`` to ``hi``, filled with ``color`` at ``opacity``, under the lines.
        Returns the artist added."""
        return self._add(Span(float(lo), float(hi), color, opacity, label=label))

    def band(self, x: ArrayLike, lo: ArrayLike, hi: ArrayLike, *, color: str = "C0", opacity: float = 0.25,
             label: str | None = None) -> Band:  # fmt: skip
        """The area between the curves ``lo`` and ``hi`` over ``x`` ((n,) each; a NaN breaks it; a lone point is a
        narrow bar), filled with ``color`` at ``opacity``, under the lines.  Returns the artist added."""
        xs, los, his = (np.asarray(a, dtype=np.float64).ravel() for a in (x, lo, hi))
        if not xs.shape == los.shape == his.shape:
            raise UsageError(f"a band needs x, lo and hi of one length, got {xs.shape}, {los.shape}, {his.shape}")
        return self._add(Band(xs, los, his, color, opacity, label=label))

    def bars(
        self, positions: ArrayLike, values: ArrayLike, *, width: float = 0.8, colors: Sequence[str] | str = "C0",
        horizontal: bool = False, label: str | None = None,
    ) -> Bars:  # fmt: skip
        """Bars from 0 (from the axis' edge on a log axis) to each value.

        Parameters
        ----------
        positions, values
            (n,) each: where each bar stands, and how far it reaches (NaN: no bar).
        width
            Each bar's width, in the units of ``positions``.
        colors
            One colour for all, or one per bar.
        horizontal
            The values run along x, the positions along y.
        label
            Its legend entry (None: not listed).

        Returns
        -------
        Bars
            The artist added.
        """
        colors = (colors,) if isinstance(colors, str) else tuple(colors)
        pos, val = np.asarray(positions, dtype=np.float64).ravel(), np.asarray(values, dtype=np.float64).ravel()
        if pos.shape != val.shape or not colors:
            raise UsageError(f"bars need positions and values of one length and a colour, got {pos.shape}, {val.shape}")
        return self._add(Bars(pos, val, float(width), colors, horizontal, label=label))

    def cells(self, fills: list[list[str]]) -> Cells:
        """Unit cells (a heat map) coloured ``fills`` (rows of ``#rrggbb``), cell (i, j) centred on x = j, y = i.
        Returns the artist added."""
        return self._add(Cells(fills))

    def gradient(self, stops: Sequence[tuple[float, str]]) -> Gradient:
        """The panel filled with a colour scale (a colour bar): ``stops`` (offset 0 at the bottom .. 1 at the top,
        ``#rrggbb``).  Returns the artist added."""
        return self._add(Gradient(tuple(stops)))

    def text(self, x: float, y: float, text: str, *, color: str = "k", size: float = FONT,
             anchor: str = "middle") -> Text:  # fmt: skip
        """``text`` at (x, y) (the axes' units), centred vertically; ``anchor`` "start", "middle" or "end"
        horizontally; ``size`` px.  Returns the artist added."""
        return self._add(Text(float(x), float(y), text, color, size, anchor))

    def set_title(self, text: str, *, size: float = TITLE, color: str = "k") -> None:
        """The title above the panel (lines split at ``\\n``), ``size`` px."""
        self.title, self.title_size, self.title_color = text, size, color

    def set_xlabel(self, text: str, *, size: float = FONT) -> None:
        """The x axis' label, ``size`` px (smaller when it would not fit the panel's width)."""
        self.x.label, self.x.label_size = text, size

    def set_ylabel(self, text: str, *, size: float = FONT) -> None:
        """The y axis' label, ``size`` px (smaller when it would not fit the panel's height)."""
        self.y.label, self.y.label_size = text, size

    def set_xlim(self, lo: float, hi: float) -> None:
        """The x limits (else from the data); ``lo`` > ``hi`` turns the axis round."""
        self.x.lim = (float(lo), float(hi))

    def set_ylim(self, lo: float, hi: float) -> None:
        """The y limits (else from the data); ``lo`` > ``hi`` turns the axis round (the first row on top)."""
        self.y.lim = (float(lo), float(hi))

    def legend(self, loc: str = "best", *, size: float = SMALL, texts: Sequence[str] = ()) -> None:
        """A legend of the labelled artists in a corner of the panel.

        Parameters
        ----------
        loc
            "best" (the corner over the fewest drawn points), "upper right", "upper left", "lower left" or
            "lower right".
        size
            Its font size, px.
        texts
            Entries that are text only, after the artists'.
        """
        if loc not in ("best", "upper right", "upper left", "lower left", "lower right"):
            raise UsageError(f"a legend's place is best or a corner (upper right, ...), got {loc!r}")
        self.legend_loc, self.legend_size, self.legend_texts = loc, size, list(texts)

    def entries(self) -> list[Entry]:
        """Its legend entries: (kind, style, label) of the first artist of each label, in order, then its text
        entries."""
        out: dict[str, Entry] = {}
        for a in self.artists:
            if a.label and a.label not in out:
                kind, style = a.handle()
                out[a.label] = (kind, style, a.label)
        return [*out.values(), *[("text", {}, t) for t in self.legend_texts]]


_SHAPES = ("o", ".", "s", "^", "v", "x")


def _check_dash(dash: str | None) -> None:
    if dash not in (None, "--", ":", "-."):
        raise UsageError(f"a line's dash is None, '--', ':' or '-.', got {dash!r}")
