"""The observer's convergence drawn: the intermediate parameters over time against their truth
(:func:`build_estimates_figure`, also as errors), and the base parameters with their std band
(:func:`build_base_convergence_figure`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from wmrid.core.errors import UsageError
from wmrid.model.base_params import recover_history
from wmrid.model.dynamics import THETA0_NAMES, RegressorForm, intermediate_parameters
from wmrid.reporting.decimate import MAX_POINTS
from wmrid.reporting.figures import _LINE, _MEDIUM, _THICK, FIGSIZE, _legend_below, _new_figure, render
from wmrid.reporting.svg import SMALL, Figure
from wmrid.reporting.svg_axes import superscript

if TYPE_CHECKING:
    from wmrid.estimators.result import IdentificationResult


def theta_units(form: RegressorForm, effort_unit: str = "N m") -> list[str]:
    """Units of theta_i1 .. theta_ip: eta_dot_i = g theta_i, so (rad/s^2) over each regressor column's unit."""
    per_column = [f"(rad/s²)/({effort_unit})"] * 2 + ["1/rad"] * 2 + ["1/s"] * 2
    per_column += ["rad/s²"] * (form.n_columns - 6)
    return per_column


def true_theta(truth: Mapping[str, Any], form: RegressorForm) -> np.ndarray:
    """theta (2, p) of the base parameters in ``truth``.

    truth : {"m11": ..., ..., "Fd2": ...} (extra keys ignored), or a simulator truth file's whole
    content, whose "parameters" table holds them.
    """
    table = truth.get("parameters", truth) if isinstance(truth.get("parameters"), Mapping) else truth
    missing = [n for n in THETA0_NAMES if n not in table]
    if missing:
        raise UsageError(f"truth lacks base parameter(s) {', '.join(missing)}; it needs {', '.join(THETA0_NAMES)}")
    # A caster's drag the truth does not give is NaN, and so are its intermediate parameters (not drawn).
    values = [float(table[n]) if n in table else math.nan for n in form.base_names]
    return intermediate_parameters(np.array(values), form)


def _display_scale(values: np.ndarray) -> tuple[float, str]:
    """(scale, unit prefix) that keep tick labels short: values / scale are drawn, in "10^n unit"."""
    finite = np.abs(values[np.isfinite(values)])
    top = float(finite.max()) if len(finite) else 0.0
    if top == 0.0:
        return 1.0, ""
    exp = math.floor(math.log10(top))
    if -2 <= exp <= 3:
        return 1.0, ""
    return 10.0**exp, f"10{superscript(exp)} "


def _subscript(text: str) -> str:
    return text.translate(str.maketrans("0123456789", "₀₁₂₃₄₅₆₇₈₉"))


def _settled_limits(t: np.ndarray, est: np.ndarray, marks: np.ndarray) -> tuple[float, float] | None:
    """y limits that leave out an estimate's early excursions, or None to show everything.

    The "settled" range covers ``marks`` (start, truth) and the estimate after the first 20 % of the
    time; when the whole range is over 3 times that, the axis shows the settled range (padded) and the
    early excursions leave the panel.
    """
    ok = np.isfinite(est)
    if len(t) < 2 or not ok.any():
        return None
    late = ok & (t >= t[0] + 0.2 * (t[-1] - t[0]))
    core = np.concatenate([marks, est[late]])
    lo, hi = float(core.min()), float(core.max())
    full = max(float(est[ok].max()), hi) - min(float(est[ok].min()), lo)
    if hi <= lo or full <= 3.0 * (hi - lo):
        return None
    pad = 0.15 * (hi - lo)
    return lo - pad, hi + pad


def build_estimates_figure(
    result: IdentificationResult, truth: Mapping[str, Any] | None = None, *, error_mode: bool = False
) -> Figure:
    """Every intermediate parameter estimate theta_ij over time, one panel each (rows: wheel i = 1, 2).

    The start value (``result.observer_settings.theta_init``) is dashed; with ``truth`` (see :func:`true_theta`)
    the true theta is dotted.  A panel whose early excursions would flatten the rest is zoomed on the
    start, the truth and the last 80 % of the estimate (its title says "zoomed"; :func:`_settled_limits`).

    Parameters
    ----------
    result
        An identification with its history (t (n,) s, theta (n, 2, p)).
    truth
        The true base parameters by name (or a truth file with a "parameters" table); None: no truth drawn.
    error_mode
        Draw the estimation error theta_hat - theta_true instead (needs ``truth``), with the start's error dashed
        and zero dotted.

    Returns
    -------
    Figure
        2 x p panels sharing the time axis, the legend below.
    """
    if error_mode and truth is None:
        raise UsageError("the estimation-error figure needs the true parameters (truth)")
    h = result.history
    form = result.form
    p = form.n_columns
    start = np.asarray(result.observer_settings.theta_init, dtype=np.float64)
    theta_true = true_theta(truth, form) if truth is not None else None
    units = theta_units(form, result.log_info.effort_unit)
    t = np.asarray(h.t, dtype=np.float64)
    fig = _new_figure(
        (max(FIGSIZE[0], 1.75 * p), 5.6), left=0.75, right=0.1, top=0.3, bottom=0.85, gaps=(0.8, 0.45), grid=(2, p),
        sharex=True,
    )  # fmt: skip
    symbol = "θ̃" if error_mode else "θ̂"
    for i in range(2):
        for k in range(p):
            ax = fig.panels[i * p + k]
            ax.x.size = ax.y.size = SMALL
            ref = theta_true[i, k] if error_mode and theta_true is not None else 0.0
            est = h.theta[:, i, k] - ref
            lines = [start[i, k] - ref] + ([0.0] if error_mode else [] if theta_true is None else [theta_true[i, k]])
            limits = _settled_limits(t, est, np.array(lines))
            scale, prefix = _display_scale(np.array(limits) if limits else np.concatenate([est, lines]))
            if error_mode:
                ax.hline(0.0, color="k", dash=":", width=_THICK, label="zero error")
            ax.line(t, est / scale, color="C0", width=_LINE, label="error of estimate" if error_mode else "estimate")
            label = "error of the start value" if error_mode else "start value"
            ax.hline((start[i, k] - ref) / scale, color="0.45", dash="--", width=1.33, label=label)
            if theta_true is not None and not error_mode:
                ax.hline(theta_true[i, k] / scale, color="k", dash=":", width=_THICK, label="true value")
            ax.set_title(f"{symbol}{_subscript(f'{i + 1}{k + 1}')}" + (" (zoomed)" if limits else ""), size=13.0)
            if limits:
                ax.set_ylim(limits[0] / scale, limits[1] / scale)
            ax.set_ylabel(f"{prefix}{units[k]}", size=SMALL)
            ax.grid = "xy"
            if i == 1:
                ax.set_xlabel("time (s)")
    if len(t) > 1:
        fig.panels[0].set_xlim(t[0], t[-1])
    _legend_below(fig, [fig.panels[0]], texts=["row i: wheel i (1 = right, 2 = left)"])
    return fig


def estimates_figure(
    result: IdentificationResult,
    truth: Mapping[str, Any] | None = None,
    *,
    error_mode: bool = False,
    fmt: str = "svg",
) -> bytes:
    """:func:`build_estimates_figure` rendered as ``fmt`` bytes."""
    return render(build_estimates_figure(result, truth, error_mode=error_mode), fmt)


def _zoom_limits(
    t: np.ndarray, est: np.ndarray, marks: np.ndarray, settled: float = 0.7
) -> tuple[float, float, bool] | None:
    """y limits (lo, hi, clipped) showing ``marks`` (final value, its band, truth) and the settled estimate.

    The settled part is the estimate over the last ``settled`` fraction of the time (its 1st to 99th percentile
    when it has 100 points or more, so that a few spikes, e.g. a recovery dividing by a near-zero m on a real log,
    do not set the scale).  When the estimate reaches more than twice as far as that range, the axis shows the
    range, padded by 10 % each side, and clipped is True (some of the estimate leaves the panel); otherwise it
    shows everything.  None when there is nothing finite to show.
    """
    ok = np.isfinite(est)
    marks = marks[np.isfinite(marks)]
    late = ok & (t >= t[-1] - settled * (t[-1] - t[0])) if len(t) else ok
    settled_values = est[late]
    if len(settled_values) >= 100:
        settled_values = np.percentile(settled_values, [1.0, 99.0])
    core = np.concatenate([marks, settled_values])
    if len(core) == 0:
        return None
    every = np.concatenate([core, est[ok]])

    def padded(values: np.ndarray) -> tuple[float, float]:
        lo, hi = float(values.min()), float(values.max())
        pad = 0.1 * (hi - lo) if hi > lo else max(0.05 * abs(hi), 1e-12)
        return lo - pad, hi + pad

    lo, hi = padded(core)
    if float(every.max() - every.min()) <= 2.0 * (hi - lo):
        return (*padded(every), False)
    return lo, hi, True


def _truth_table(truth: Mapping[str, Any] | None) -> Mapping[str, Any]:
    if truth is None:
        return {}
    return truth["parameters"] if isinstance(truth.get("parameters"), Mapping) else truth


def _finite(x: Any) -> float:
    """``x`` as a float, NaN when it is None, not a number, or infinite."""
    try:
        v = float(x)
    except (TypeError, ValueError):
        return math.nan
    return v if math.isfinite(v) else math.nan


def build_base_convergence_figure(
    result: IdentificationResult, truth: Mapping[str, float] | None = None
) -> Figure | None:
    """The base parameters over time, one panel each (2 rows), converging to the final estimate.

    Each point of the recorded history theta(t) is turned into base parameters by the closed form
    :func:`wmrid.model.base_params.direct_recovery` (the start of the reported fit).  Each panel shows how far the
    estimate is from the final one in units of its std, (estimate - final) / std: the final estimate is the zero line,
    its +-2 std band runs from -2 to 2, the truth is a dotted black line, and the panel's title gives the final value
    and std.  Where the std is undefined the distance is in % of the final value (a y label says which).  A panel
    whose early transient would flatten the rest is zoomed on the band, the truth and the last 70 % of the estimate
    (its title says "zoomed"; :func:`_zoom_limits`).

    Parameters
    ----------
    result
        An identification; its history (t (n,) s, theta (n, 2, p)) is drawn.
    truth
        The true base parameters ({name: value}, or a truth file with a "parameters" table); None: none drawn.

    Returns
    -------
    Figure or None
        2 rows of at least 4 panels sharing the time axis, the legend below; None when the result has no history.
    """
    h = result.history
    if h is None:
        return None
    form = result.form
    names = form.base_names
    t = np.asarray(h.t, dtype=np.float64)
    theta = np.asarray(h.theta, dtype=np.float64)
    if len(t) > MAX_POINTS // 2:  # recovered at evenly spaced points (the last included): a line's display budget
        keep = np.unique(np.linspace(0, len(t) - 1, MAX_POINTS // 2).round().astype(int))
        t, theta = t[keep], theta[keep]
    base = recover_history(theta, form)
    table = _truth_table(truth)
    ncols = max(4, -(-len(names) // 2))
    fig = _new_figure(
        (max(FIGSIZE[0], 2.3 * ncols), 5.8), left=0.75, right=0.1, top=0.5, bottom=0.85, gaps=(0.75, 0.6),
        grid=(2, ncols), sharex=True,
    )  # fmt: skip
    for ax in fig.panels[len(names) :]:  # unused panels
        fig.remove(ax)
    for j, name in enumerate(names):
        ax = fig.panels[j]
        value, std = result.parameters.get(name, (math.nan, math.nan))
        value, std = _finite(value), _finite(std)
        true = _finite(table.get(name))
        unit = result.units.get(name, "")
        if math.isfinite(value) and math.isfinite(std) and std > 0.0:
            scale, ylabel, band = std, "(estimate − final) / σ", True
        elif math.isfinite(value) and value != 0.0:
            scale, ylabel, band = abs(value) / 100.0, "estimate − final, %", False
        else:
            scale, ylabel, band = 1.0, unit, False
        ref = value if math.isfinite(value) else 0.0
        est = (base[:, j] - ref) / scale
        true_z = (true - ref) / scale if math.isfinite(true) else math.nan
        marks = ([0.0] if math.isfinite(value) else []) + ([-2.0, 2.0] if band else []) + [true_z]
        limits = _zoom_limits(t, est, np.array(marks))
        ax.line(t, est, color="C0", width=_MEDIUM, label="estimate (closed form)")
        if band:
            ax.hspan(-2.0, 2.0, color="C3", opacity=0.18, label="final ± 2σ")
        if math.isfinite(value):
            ax.hline(0.0, color="C3", width=_MEDIUM, label="final estimate")
        if math.isfinite(true_z):
            ax.hline(true_z, color="k", dash=":", width=_THICK, label="true value")
        zoomed = bool(limits and limits[2])
        final = f"{value:.6g} ± {std:.2g}" if band else f"{value:.6g}"
        ax.set_title(f"{name}" + (" (zoomed)" if zoomed else "") + f"\n{final} {unit}", size=SMALL)
        if limits:
            ax.set_ylim(limits[0], limits[1])
        ax.set_ylabel(ylabel)
        ax.grid = "xy"
        if j >= len(names) - ncols:  # no panel below: this one shows the time axis
            ax.set_xlabel("time (s)")
    if len(t) > 1:
        fig.panels[0].set_xlim(t[0], t[-1])
    _legend_below(fig)
    return fig


def base_convergence_figure(
    result: IdentificationResult, truth: Mapping[str, float] | None = None, fmt: str = "svg"
) -> bytes | None:
    """:func:`build_base_convergence_figure` rendered as ``fmt`` bytes; None when the result has no history."""
    fig = build_base_convergence_figure(result, truth)
    return None if fig is None else render(fig, fmt)
