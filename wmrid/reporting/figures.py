"""Figures of a log and of an identification: pure functions from data to SVG or PNG bytes.

Each figure has a ``build_*`` function returning a :class:`matplotlib.figure.Figure` (for tests and
for callers who want to adjust it) and a function of the same name without the prefix that renders it
(:func:`render`).  matplotlib is imported lazily, figures are made with ``Figure`` and the Agg canvas,
never with pyplot, so no global figure state is created or left behind.

No line carries more than :data:`MAX_POINTS` points: long series are reduced for display only by
:func:`wmrid.reporting.decimate.decimate_for_display`, which keeps the minimum and maximum of every bin, so spikes
stay visible.

Colours: right wheel blue (C0), left wheel orange (C1), in every figure.

The report shows each figure under its own caption, at the full width of the page (FIGSIZE is that
width): no figure has a figure-level title, and no title repeats the log's name.  SVG keeps its text
as ``<text>`` elements (selectable, searchable), not as glyph outlines.
"""

from __future__ import annotations

import functools
import io
import warnings
from typing import TYPE_CHECKING, Any

import numpy as np

from wmrid.core.errors import UsageError
from wmrid.reporting.decimate import MAX_POINTS, decimate_for_display, envelope_indices

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure


#: Figure size (inches) of the single-panel and side-by-side figures (the full width of a report page),
#: and the PNG resolution.
FIGSIZE = (11.0, 4.2)
#: Figure size (inches) of the figures with two panels stacked.
FIGSIZE_STACKED = (11.0, 5.6)
PNG_DPI = 120
FORMATS = ("svg", "png")

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
) -> Figure:
    """A figure whose panels (a ``grid`` of rows x columns) sit at fixed margins, inches: ``left`` (tick labels and
    the y label), ``right``, ``top`` (titles), ``bottom`` (the x label, and a legend row below it), ``gaps``
    (between columns, between rows).

    Fixed margins, not matplotlib's constrained layout: laying the report's figures out took 8 of its 18 s
    (bench/speed/bench_report.py), measuring every tick label again and again; the margins here fit the labels drawn.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # matplotlib (~0.3 s, no pyplot): only figures
    from matplotlib.figure import Figure  # matplotlib: only figures

    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    w, h = figsize
    rows, cols = grid
    panel_w = (w - left - right - (cols - 1) * gaps[0]) / cols
    panel_h = (h - top - bottom - (rows - 1) * gaps[1]) / rows
    fig.subplots_adjust(
        left=left / w, right=1 - right / w, top=1 - top / h, bottom=bottom / h,
        wspace=gaps[0] / panel_w, hspace=gaps[1] / panel_h,
    )  # fmt: skip
    return fig


#: matplotlib settings every figure is built with: titles at a fixed height above their panel (matplotlib otherwise
#: measures every panel's tick labels to place each title, a fifth of the drawing time).
_STYLE = {"axes.titley": 1.0, "axes.titlepad": 4.0}


def _styled(build: Any) -> Any:
    """``build`` (a ``build_*`` function) run with :data:`_STYLE`."""

    @functools.wraps(build)
    def styled(*args: Any, **kwargs: Any) -> Any:
        import matplotlib  # matplotlib (~0.1 s): only figures

        with matplotlib.rc_context(_STYLE):
            return build(*args, **kwargs)

    return styled


def _legend_below(fig: Figure, handles: list[Any], labels: list[str], ncols: int) -> None:
    """The legend in one row along the bottom edge (the margin ``bottom`` of :func:`_new_figure` keeps room)."""
    fig.legend(handles, labels, loc="lower center", ncols=ncols, fontsize="small", frameon=False, borderaxespad=0.2)


def _freeze_layout(fig: Figure) -> None:
    """Lay ``fig`` out once and keep that layout (its layout engine is then "none").

    The constrained layout, run on every draw, moves the axes by a rounding error from one draw to the
    next, so the same figure saved twice would differ in the last digit of some coordinates.  A caller
    who changes the figure after rendering it can lay it out again with
    ``fig.set_layout_engine("constrained")``.
    """
    from matplotlib.layout_engine import PlaceHolderLayoutEngine  # matplotlib: only figures

    engine = fig.get_layout_engine()
    if engine is not None and not isinstance(engine, PlaceHolderLayoutEngine):
        fig.draw_without_rendering()
        fig.set_layout_engine("none")


def render(fig: Figure, fmt: str = "svg") -> bytes:
    """The figure as ``fmt`` bytes: "svg" (deterministic: no date, fixed ids; text kept as ``<text>``, not
    glyph paths) or "png" (PNG_DPI dpi).

    The first render fixes the figure's layout (:func:`_freeze_layout`), so rendering it again gives the
    same bytes, as does rendering a figure built from the same data.
    """
    if fmt not in FORMATS:
        raise UsageError(f"figure format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    import matplotlib  # matplotlib (~0.1 s): only figures

    buf = io.BytesIO()
    # matplotlib's own advice on drawing (a date range its tick locator has no interval for, ...) is for its
    # programmers, not for wmrid's users: kept off their terminal (issue 30)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # matplotlib attributes them to its caller: wmrid
        _freeze_layout(fig)
        if fmt == "svg":
            with matplotlib.rc_context({"svg.hashsalt": "wmrid", "svg.fonttype": "none"}):
                fig.savefig(buf, format="svg", metadata={"Date": None})
        else:
            fig.savefig(buf, format="png", dpi=PNG_DPI, metadata={"Software": None})
    return buf.getvalue()


def _plot(ax: Axes, t: np.ndarray, y: np.ndarray, **kwargs: Any) -> None:
    td, yd = decimate_for_display(np.asarray(t, dtype=np.float64), np.asarray(y, dtype=np.float64))
    ax.plot(td, yd, **kwargs)


# --------------------------------------------------------------------------------------------------
# 1. The log: torques and speeds (paper Fig. 6)


@_styled
def build_log_overview(log: Any) -> Figure:
    """Wheel efforts and wheel speeds over time, right and left, two panels sharing the time axis.

    log : a WheelLog-like object (t (n,) s, eta (n, 2) rad/s, tau (n, 2) in ``effort_unit``, default
    N m, source).  Time is drawn from the first sample.
    """
    t = np.asarray(log.t, dtype=np.float64)
    eta = np.asarray(log.eta, dtype=np.float64)
    tau = np.asarray(log.tau, dtype=np.float64)
    unit = getattr(log, "effort_unit", "N m")
    t = t - t[0]
    fig = _new_figure(FIGSIZE_STACKED, bottom=0.85, gaps=(0.0, 0.15), grid=(2, 1))
    ax_tau, ax_eta = fig.subplots(2, 1, sharex=True)
    for j, (wheel, colour) in enumerate(_WHEELS):
        _plot(ax_tau, t, tau[:, j], color=colour, lw=0.9, label=f"{wheel} wheel")
        _plot(ax_eta, t, eta[:, j], color=colour, lw=0.9, label=f"{wheel} wheel")
    what = "torque" if unit == "N m" else "effort"
    ax_tau.set_ylabel(f"wheel {what} ({unit})")
    ax_eta.set_ylabel("wheel speed (rad/s)")
    ax_eta.set_xlabel("time since first sample (s)")
    for ax in (ax_tau, ax_eta):
        ax.grid(alpha=0.3)
    handles, labels = ax_tau.get_legend_handles_labels()
    _legend_below(fig, handles, labels, 2)
    ax_eta.set_xlim(t[0], t[-1])
    return fig


def log_overview(log: Any, fmt: str = "svg") -> bytes:
    """:func:`build_log_overview` rendered as ``fmt`` bytes."""
    return render(build_log_overview(log), fmt)


# --------------------------------------------------------------------------------------------------
# 2. The path (paper Fig. 5)


@_styled
def build_path_figure(pose: np.ndarray | None) -> Figure | None:
    """The x-y path (m), equal aspect, start and end marked; None when ``pose`` is None.

    pose : (n, 3) [x m, y m, phi rad] (only x and y are drawn; (n, 2) is accepted too).
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
    ax = fig.subplots()
    ax.plot(x[idx], y[idx], color="C0", lw=1.2, label="path")
    ax.plot(x[0], y[0], "o", color="C2", ms=8, label="start", zorder=3)
    ax.plot(x[-1], y[-1], "s", color="C3", ms=8, label="end", zorder=3)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    return fig


def path_figure(pose: np.ndarray | None, fmt: str = "svg") -> bytes | None:
    """:func:`build_path_figure` rendered as ``fmt`` bytes; None when ``pose`` is None."""
    fig = build_path_figure(pose)
    return None if fig is None else render(fig, fmt)


# --------------------------------------------------------------------------------------------------
# 3. Intermediate parameter estimates over time (paper Fig. 7)


# --------------------------------------------------------------------------------------------------
# 4. Prediction errors


# --------------------------------------------------------------------------------------------------
# 7. Measured and predicted wheel speeds
