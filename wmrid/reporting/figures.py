"""Figures of a log and of an identification: pure functions from data to SVG bytes.

Each figure has a ``build_*`` function returning a :class:`wmrid.reporting.svg.Figure` (for tests and for callers
who want to adjust it) and a function of the same name without the prefix that renders it (:func:`render`).  The
figures are drawn by wmrid's own SVG layer (:mod:`wmrid.reporting.svg`): numpy and the standard library only.

No line carries more than :data:`MAX_POINTS` points: long series are reduced for display only by
:func:`wmrid.reporting.decimate.decimate_for_display`, which keeps the minimum and maximum of every bin, so spikes
stay visible (:meth:`wmrid.reporting.svg.Panel.line` does it).

Colours: right wheel blue (C0), left wheel orange (C1), in every figure.

The report shows each figure under its own caption, at the full width of the page (FIGSIZE is that
width): no figure has a figure-level title, and no title repeats the log's name.  SVG keeps its text
as ``<text>`` elements (selectable, searchable), not as glyph outlines.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from wmrid.core.errors import UsageError
from wmrid.reporting.decimate import MAX_POINTS, envelope_indices
from wmrid.reporting.svg import Figure, Panel

#: Figure size (inches, at 96 px per inch) of the single-panel and side-by-side figures (the full width of a report
#: page).
FIGSIZE = (11.0, 4.2)
#: Figure size (inches) of the figures with two panels stacked.
FIGSIZE_STACKED = (11.0, 5.6)
#: The formats a figure renders to.
FORMATS = ("svg",)

_WHEELS = (("right", "C0"), ("left", "C1"))
#: lambda_min(Gamma) / alpha from which the data outweigh the start value (see excitation_figure).
_OUTWEIGH = 100.0


# --------------------------------------------------------------------------------------------------
# Rendering


def _new_figure(
    figsize: tuple[float, float] = FIGSIZE,
    *,
    left: float = 0.8,
    right: float = 0.2,
    top: float = 0.15,
    bottom: float = 0.55,
    gaps: tuple[float, float] = (0.0, 0.0),
    grid: tuple[int, int] = (1, 1),
    width_ratios: Sequence[float] | None = None,
    sharex: bool = False,
    sharey: bool = False,
) -> Figure:
    """A figure whose panels (a ``grid`` of rows x columns) sit at fixed margins, inches: ``left`` (tick labels and
    the y label), ``right``, ``top`` (titles), ``bottom`` (the x label, and a legend row below it), ``gaps``
    (between columns, between rows); ``sharex``/``sharey`` as :class:`wmrid.reporting.svg.Figure`."""
    return Figure(
        figsize, grid=grid, left=left, right=right, top=top, bottom=bottom, gaps=gaps, width_ratios=width_ratios,
        sharex=sharex, sharey=sharey,
    )  # fmt: skip


def _legend_below(fig: Figure, panels: Sequence[Panel] | None = None, texts: Sequence[str] = ()) -> None:
    """The legend of ``panels`` (default: all; the first entry of each label) in a row along the bottom edge, then
    ``texts`` as text-only entries (the margin ``bottom`` of :func:`_new_figure` keeps room)."""
    fig.legend_below([*fig.entries(panels), *[("text", {}, t) for t in texts]])


def check_format(fmt: str) -> None:
    """Raise :class:`~wmrid.core.errors.UsageError` unless ``fmt`` is a figure format wmrid draws ("svg")."""
    if fmt not in FORMATS:
        raise UsageError(f"figure format must be svg (the only one wmrid draws), got {fmt!r}")


def render(fig: Figure, fmt: str = "svg") -> bytes:
    """The figure as ``fmt`` bytes.

    Parameters
    ----------
    fig
        A figure of :mod:`wmrid.reporting.svg`.
    fmt
        "svg", the only format.

    Returns
    -------
    bytes
        A standalone SVG document (UTF-8), deterministic: no date, ids derived from the content, text kept as
        ``<text>``.

    Raises
    ------
    UsageError
        Any other format.
    """
    check_format(fmt)
    return fig.to_svg()


#: Line widths, px: thin, normal, medium, thick (0.9, 1.1, 1.2 and 1.4 pt at 96 px per inch).
_THIN, _LINE, _MEDIUM, _THICK = 1.2, 1.5, 1.6, 1.9


# --------------------------------------------------------------------------------------------------
# 1. The log: torques and speeds (paper Fig. 6)


def build_log_overview(log: Any) -> Figure:
    """Wheel efforts and wheel speeds over time, right and left, two panels sharing the time axis.

    Parameters
    ----------
    log
        A WheelLog-like object: t (n,) s, eta (n, 2) rad/s, tau (n, 2) in ``effort_unit`` (default N m), source.
        Time is drawn from the first sample.

    Returns
    -------
    Figure
        Efforts above, speeds below, the legend below them.
    """
    t = np.asarray(log.t, dtype=np.float64)
    eta = np.asarray(log.eta, dtype=np.float64)
    tau = np.asarray(log.tau, dtype=np.float64)
    unit = getattr(log, "effort_unit", "N m")
    t = t - t[0]
    fig = _new_figure(FIGSIZE_STACKED, bottom=0.85, gaps=(0.0, 0.15), grid=(2, 1), sharex=True)
    ax_tau, ax_eta = fig.panels
    for j, (wheel, colour) in enumerate(_WHEELS):
        ax_tau.line(t, tau[:, j], color=colour, width=_THIN, label=f"{wheel} wheel")
        ax_eta.line(t, eta[:, j], color=colour, width=_THIN, label=f"{wheel} wheel")
    what = "torque" if unit == "N m" else "effort"
    ax_tau.set_ylabel(f"wheel {what} ({unit})")
    ax_eta.set_ylabel("wheel speed (rad/s)")
    ax_eta.set_xlabel("time since first sample (s)")
    for ax in (ax_tau, ax_eta):
        ax.grid = "xy"
    _legend_below(fig, [ax_tau])
    ax_eta.set_xlim(t[0], t[-1])
    return fig


def log_overview(log: Any, fmt: str = "svg") -> bytes:
    """:func:`build_log_overview` rendered as ``fmt`` bytes."""
    return render(build_log_overview(log), fmt)


# --------------------------------------------------------------------------------------------------
# 2. The path (paper Fig. 5)


def build_path_figure(pose: np.ndarray | None) -> Figure | None:
    """The x-y path (m), equal aspect, start and end marked; None when ``pose`` is None.

    Parameters
    ----------
    pose
        (n, 3) [x m, y m, phi rad] (only x and y are drawn; (n, 2) is accepted too), or None.

    Returns
    -------
    Figure or None
        One panel: the path (at most MAX_POINTS points, every bin's extremes of x and of y kept), start and end.
    """
    if pose is None:
        return None
    pose = np.asarray(pose, dtype=np.float64)
    if pose.ndim != 2 or pose.shape[1] < 2 or len(pose) < 1:
        raise UsageError(f"pose must have shape (n, 3) [x, y, phi], got {pose.shape}")
    x, y = pose[:, 0], pose[:, 1]
    half = MAX_POINTS // 2
    idx = np.union1d(envelope_indices(x, half), envelope_indices(y, half))
    fig = _new_figure(bottom=0.6)
    (ax,) = fig.panels
    ax.line(x[idx], y[idx], color="C0", width=_MEDIUM, label="path", decimate=False)
    ax.markers(x[0], y[0], shape="o", color="C2", size=10.0, label="start")
    ax.markers(x[-1], y[-1], shape="s", color="C3", size=10.0, label="end")
    ax.equal = True
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid = "xy"
    ax.legend("best")
    return fig


def path_figure(pose: np.ndarray | None, fmt: str = "svg") -> bytes | None:
    """:func:`build_path_figure` rendered as ``fmt`` bytes; None when ``pose`` is None."""
    fig = build_path_figure(pose)
    return None if fig is None else render(fig, fmt)
