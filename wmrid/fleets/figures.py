"""Figures of a fleet review: each robot's parameters over its logs with ±2σ bands, its baseline and the change
found (:func:`build_robot_figure`), and the evidence against every robot (:func:`build_evidence_figure`).

Same conventions as :mod:`wmrid.reporting.figures`: :class:`wmrid.reporting.svg.Figure` objects, no figure-level
title, rendered by :func:`wmrid.reporting.figures.render`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from wmrid.model.dynamics import THETA0_UNITS
from wmrid.reporting.figures import _new_figure
from wmrid.reporting.svg import Figure
from wmrid.reporting.svg_axes import date_number

if TYPE_CHECKING:
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
#: Font sizes (px) of the robot figure's tick labels and titles: small panels, ten of them.
_TICKS, _TITLES = 9.5, 12.0


def _x(review: RobotReview) -> tuple[np.ndarray, str]:
    """The horizontal axis: the logs' start times as date numbers (:func:`wmrid.reporting.svg_axes.date_number`;
    any date from year 1 to 9999) when every log has one, else their order."""
    times = [r["start_time"] for r in review.rows]
    if times and all(t is not None for t in times):
        return np.array([date_number(t) for t in times]), "date"
    return np.arange(len(review.rows), dtype=float), "log"


def build_robot_figure(review: RobotReview) -> Figure | None:
    """One robot's watched parameters over its logs.

    Eight panels (M11 M12 M22 Vc / Fv1 Fv2 Fd1 Fd2), and Fw1 / Fw2 in a fifth column when the review has the
    wheels' friction at their typical speeds: each log's estimate with its ±2σ band (a narrow bar for a robot with
    a single log), the mean of the logs before the change (dashed), the change's onset (dotted) and the log that
    first flagged it (red); odd logs as crosses.

    Parameters
    ----------
    review
        The robot's review (its rows in time order, its history of changes).

    Returns
    -------
    Figure or None
        The panels sharing a date axis (the logs' order, 0, 1, 2 ..., when a log has no start time); None for a
        robot without usable logs.
    """
    if not review.rows:
        return None
    x, kind = _x(review)
    extra = [n for n in ("Fw1", "Fw2") if n in review.wheel_friction]
    panels = [list(row) + ([extra[k]] if k < len(extra) and len(extra) == 2 else []) for k, row in enumerate(_PANELS)]
    fig = _new_figure((11.0, 4.6), left=0.7, right=0.1, top=0.3, bottom=0.5, gaps=(0.75, 0.45),
                      grid=(2, len(panels[0])), sharex=True)  # fmt: skip
    change = review.history.changes[0] if review.history.changes else None
    odd = set(review.history.odd_logs)
    for ax, name in zip(fig.panels, [n for row in panels for n in row], strict=True):
        ax.x.size = ax.y.size = _TICKS
        ax.x.scale = "date" if kind == "date" else "linear"
        ax.x.integer = kind == "log"  # logs 0, 1, 2 ...: never a tick at 0.5
        y, s = review.series(name)
        s = np.where(np.isfinite(s), s, 0.0)
        changed = change is not None and name in change.parameters
        color = "C3" if changed else "C0"
        ax.band(x, y - 2 * s, y + 2 * s, color=color, opacity=0.25)
        keep = np.array([i not in odd for i in range(len(y))])
        ax.line(x[keep], y[keep], color=color, width=1.1, decimate=False)
        ax.markers(x[keep], y[keep], shape=".", color=color, size=4.0)
        if odd:
            idx = sorted(odd)
            ax.markers(x[idx], y[idx], shape="x", color="0.3", size=8.0)
        stop = change.onset if change is not None else len(y)
        base = y[:stop][keep[:stop]]
        if base.size:
            ax.hline(float(base.mean()), color="0.4", dash="--", width=1.1)
        finite = y[np.isfinite(y)]
        if finite.size > 1 and np.ptp(finite) > 0 and 4 * np.max(s) > 10 * np.ptp(finite):
            # bands far wider than the logs' spread (a model error common to every log): the band fills the panel
            # and the axis follows the values, so that their trend stays visible
            lo, hi = float(finite.min()), float(finite.max())
            ax.set_ylim(lo - 1.5 * (hi - lo), hi + 1.5 * (hi - lo))
        if change is not None:
            ax.vline(x[change.onset], color="0.3", dash=":", width=1.33)
            ax.vline(x[change.alarm], color="C3", width=1.33)
        speed = f" at {review.wheel_friction[name][0]:.3g} rad/s" if name in review.wheel_friction else ""
        ax.set_title(f"{name}{speed} ({UNITS[name]})", size=_TITLES, color="C3" if changed else "k")
        if kind == "log" and ax.cell is not None and ax.cell[0] == 1:
            ax.set_xlabel("log", size=_TICKS)
    return fig


def build_evidence_figure(review: FleetReview) -> Figure | None:
    """The evidence against each robot (its largest statistic over its threshold), ranked; 1 is the flag line.

    Parameters
    ----------
    review
        The fleet's review, its robots ranked.

    Returns
    -------
    Figure or None
        Horizontal bars on a log axis, the first robot at the top (red: flagged), as many robots as fit 14 inches;
        None without robots.
    """
    robots = review.robots
    if not robots:
        return None
    height = min(1.2 + 0.22 * len(robots), 14.0)
    fig = _new_figure((11.0, height))
    (ax,) = fig.panels
    shown = robots[: int((height - 1.2) / 0.22)] if len(robots) * 0.22 + 1.2 > height else robots
    names = [r.robot_id for r in shown][::-1]
    values = [max(r.evidence, 1e-3) if math.isfinite(r.evidence) else math.nan for r in shown][::-1]
    colors = ["C3" if r.flagged else "C0" for r in shown][::-1]
    rows = np.arange(len(names), dtype=float)
    ax.bars(rows, values, colors=colors, horizontal=True)
    ax.vline(1.0, color="0.2", dash="--", width=1.33)
    ax.x.scale = "log"
    ax.y.ticks = (rows.tolist(), names)
    ax.set_ylim(-0.6, len(names) - 0.4)
    ax.y.size = 9.5 if len(shown) > 30 else 12.0
    ax.set_xlabel("evidence (statistic / threshold; > 1: flagged)")
    return fig
