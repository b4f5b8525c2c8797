"""Figures of a fleet review: each robot's parameters over its logs with ±2σ bands, its baseline and the change
found (:func:`build_robot_figure`), and the evidence against every robot (:func:`build_evidence_figure`).

Same conventions as :mod:`wmrid.reporting.figures`: ``Figure`` objects on the Agg canvas (no pyplot), no
figure-level title, rendered by :func:`wmrid.reporting.figures.render`.
"""

from __future__ import annotations

import datetime as dt
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from wmrid.model.dynamics import THETA0_UNITS
from wmrid.reporting.figures import _new_figure

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from wmrid.fleets.review import FleetReview, RobotReview

#: The panels' units: the model's own table (``Vc`` kg m², ``Fv`` N m s/rad), and a wheel's friction torque at its
#: typical speed (Fw, N m).
UNITS = {
    **{k: THETA0_UNITS[k].replace("^2", "²") for k in ("M11", "M12", "M22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")},
    "Fw1": "N m", "Fw2": "N m",
}  # fmt: skip
#: The panels, row by row: the inertial parameters and the friction, with each wheel's friction at its typical
#: speed in a fifth column when the review has it (right wheel's on top).
_PANELS = (("M11", "M12", "M22", "Vc"), ("Fv1", "Fv2", "Fd1", "Fd2"))


#: Start times a date axis shows (naive UTC); others (a forged 0001-01-01 or 9999-12-31: matplotlib's date axis
#: ends at years 1 and 9999, and its margins and ticks reach beyond the data) put the logs in their order instead.
DATE_AXIS_SPAN = (dt.datetime(1900, 1, 1), dt.datetime(2300, 1, 1))


def _x(review: RobotReview) -> tuple[Any, str]:
    """The horizontal axis: the logs' start times (when all lie in :data:`DATE_AXIS_SPAN`), else their order."""
    times = [r["start_time"] for r in review.rows]
    if times and all(t is not None for t in times):
        naive = [t.astimezone(dt.timezone.utc).replace(tzinfo=None) if t.tzinfo else t for t in times]
        if all(DATE_AXIS_SPAN[0] <= t <= DATE_AXIS_SPAN[1] for t in naive):
            import matplotlib.dates as mdates  # matplotlib (~0.1 s): only figures

            return mdates.date2num(naive), "date"
    return np.arange(len(review.rows), dtype=float), "log"


def build_robot_figure(review: RobotReview) -> Figure | None:
    """Eight panels (M11 M12 M22 Vc / Fv1 Fv2 Fd1 Fd2), and Fw1 / Fw2 in a fifth column when the review has the
    wheels' friction at their typical speeds: each log's estimate with its ±2σ band, the mean of the logs before
    the change (dashed), the change's onset (dotted) and the log that first flagged it (red); odd logs as crosses.
    None for a robot without usable logs."""
    if not review.rows:
        return None
    x, kind = _x(review)
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # matplotlib (~0.3 s): only figures
    from matplotlib.figure import Figure  # matplotlib: only figures

    # a fixed layout: the constrained one took 0.7 s of a robot's 1.2 s, and every robot's panels are alike
    fig = Figure(figsize=(11.0, 4.6))
    FigureCanvasAgg(fig)
    fig.subplots_adjust(left=0.06, right=0.995, bottom=0.11, top=0.93, wspace=0.42, hspace=0.32)
    extra = [n for n in ("Fw1", "Fw2") if n in review.wheel_friction]
    panels = [list(row) + ([extra[k]] if k < len(extra) and len(extra) == 2 else []) for k, row in enumerate(_PANELS)]
    axes = fig.subplots(2, len(panels[0]), sharex=True)
    change = review.history.changes[0] if review.history.changes else None
    odd = set(review.history.odd_logs)
    for ax, name in zip(axes.flat, [n for row in panels for n in row], strict=True):
        y, s = review.series(name)
        s = np.where(np.isfinite(s), s, 0.0)
        changed = change is not None and name in change.parameters
        color = "C3" if changed else "C0"
        ax.fill_between(x, y - 2 * s, y + 2 * s, color=color, alpha=0.25, linewidth=0, step=None)
        keep = np.array([i not in odd for i in range(len(y))])
        ax.plot(x[keep], y[keep], ".-", color=color, markersize=3, linewidth=0.8)
        if odd:
            idx = sorted(odd)
            ax.plot(x[idx], y[idx], "x", color="0.3", markersize=6)
        stop = change.onset if change is not None else len(y)
        base = y[:stop][keep[:stop]]
        if base.size:
            ax.axhline(float(base.mean()), color="0.4", linestyle="--", linewidth=0.8)
        finite = y[np.isfinite(y)]
        if finite.size > 1 and np.ptp(finite) > 0 and 4 * np.max(s) > 10 * np.ptp(finite):
            # bands far wider than the logs' spread (a model error common to every log): the band fills the panel
            # and the axis follows the values, so that their trend stays visible
            lo, hi = float(finite.min()), float(finite.max())
            ax.set_ylim(lo - 1.5 * (hi - lo), hi + 1.5 * (hi - lo))
        if change is not None:
            ax.axvline(x[change.onset], color="0.3", linestyle=":", linewidth=1.0)
            ax.axvline(x[change.alarm], color="C3", linewidth=1.0)
        speed = f" at {review.wheel_friction[name][0]:.3g} rad/s" if name in review.wheel_friction else ""
        ax.set_title(f"{name}{speed} ({UNITS[name]})", fontsize=9, color="C3" if changed else "black")
        ax.tick_params(labelsize=7)
        ax.yaxis.get_offset_text().set_fontsize(7)
    if kind == "date":
        import matplotlib.dates as mdates  # matplotlib: only figures

        for ax in axes[1]:
            ax.xaxis.set_major_locator(mdates.AutoDateLocator(maxticks=5))
            ax.xaxis.set_major_formatter(mdates.ConciseDateFormatter(ax.xaxis.get_major_locator()))
    else:
        for ax in axes[1]:
            ax.set_xlabel("log", fontsize=8)
    return fig


def build_evidence_figure(review: FleetReview) -> Figure | None:
    """The evidence against each robot (largest statistic over its threshold), ranked; 1 is the flag line."""
    robots = review.robots
    if not robots:
        return None
    height = min(1.2 + 0.22 * len(robots), 14.0)
    fig = _new_figure((11.0, height))
    ax = fig.subplots()
    shown = robots[: int((height - 1.2) / 0.22)] if len(robots) * 0.22 + 1.2 > height else robots
    names = [r.robot_id for r in shown][::-1]
    values = [max(r.evidence, 1e-3) if math.isfinite(r.evidence) else 0.0 for r in shown][::-1]
    colors = ["C3" if r.flagged else "C0" for r in shown][::-1]
    ax.barh(names, values, color=colors)
    ax.axvline(1.0, color="0.2", linestyle="--", linewidth=1.0)
    ax.set_xscale("log")
    ax.set_xlabel("evidence (statistic / threshold; > 1: flagged)")
    ax.tick_params(axis="y", labelsize=7 if len(shown) > 30 else 9)
    return fig
