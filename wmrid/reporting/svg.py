"""wmrid's own plotting layer: figures drawn straight to SVG, with numpy and the standard library only.

A :class:`Figure` has a fixed size (inches at :data:`PX_PER_INCH`; a ``viewBox`` lets it scale to the page's width)
and panels on a grid at fixed margins (or at given boxes).  A :class:`Panel` (:mod:`wmrid.reporting.svg_panel`) draws
lines (NaN breaks them; long series reduced by :func:`wmrid.reporting.decimate.decimate_for_display`, so no line has
more than :data:`~wmrid.reporting.decimate.MAX_POINTS` points), markers, horizontal and vertical lines, spans, bands,
bars, cells and text (:mod:`wmrid.reporting.svg_artists`) on linear, log10 or date axes with nice ticks
(:mod:`wmrid.reporting.svg_axes`), clipped to its box; a legend sits in a corner of a panel or in rows below the
panels (:mod:`wmrid.reporting.svg_draw` draws it all).  Text stays text (``<text>``, sans-serif), escaped.  The same
figure gives the same bytes: no date, no random id (ids are derived from the content, so several figures in one page
never share one).
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence

import numpy as np

from wmrid.reporting.svg_artists import Entry
from wmrid.reporting.svg_draw import draw_figure
from wmrid.reporting.svg_panel import Axis, Panel
from wmrid.reporting.svg_style import FONT, ID_PLACEHOLDER, SMALL, TITLE, num

__all__ = ["FONT", "PX_PER_INCH", "SMALL", "TITLE", "Axis", "Entry", "Figure", "Panel"]

#: px per inch of a figure's size (the CSS px).
PX_PER_INCH = 96.0


class Figure:
    """A figure of fixed size with panels on a grid at fixed margins (no layout pass: the margins fit the labels).

    Parameters
    ----------
    size
        (width, height), inches (at :data:`PX_PER_INCH`).
    grid
        (rows, columns) of panels; ``panels`` lists them row by row (:meth:`add_panel` places one at a box of its
        own).
    left, right, top, bottom
        Margins, inches: ``left`` holds the tick labels and the y label, ``top`` the titles, ``bottom`` the x label
        and a legend row below it.
    gaps
        (between columns, between rows), inches.
    width_ratios
        The columns' relative widths (default: equal).
    sharex, sharey
        Every panel has the same x (y) limits, and only the panels at the bottom of their column (at the left of
        their row) label those ticks.
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
        """The panels drawn (those not removed), in order."""
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
        """The figure drawn.

        Returns
        -------
        bytes
            A standalone SVG document, UTF-8: an XML declaration, then ``<svg>`` with width, height and a
            ``viewBox`` (px) so that it scales to the page's width.  The same figure gives the same bytes; its
            ids are derived from its content (no two figures of a page share one).
        """
        body, height = draw_figure(
            self.visible, sharex=self.sharex, sharey=self.sharey, below=self.below, size=(self.width, self.height)
        )
        digest = hashlib.sha256(body.encode("utf-8")).hexdigest()[:10]
        body = body.replace(ID_PLACEHOLDER, f"w{digest}-")
        w, h = num(self.width), num(height)
        return (
            '<?xml version="1.0" encoding="utf-8"?>\n'
            f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" '
            f'font-family="sans-serif" stroke-linejoin="round">\n'
            f'<rect width="{w}" height="{h}" fill="#ffffff"/>\n{body}</svg>\n'
        ).encode()
