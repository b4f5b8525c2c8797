"""Figures of how well an identification fits its log: the prediction errors, the excitation over time, the wheel
speeds the model predicts against the logged ones, and the parameters' correlations.

The same conventions as :mod:`wmrid.reporting.figures` (a ``build_*`` function returning a
:class:`wmrid.reporting.svg.Figure` and a function of the same name without the prefix that renders it; right wheel
C0, left C1; no line over :data:`~wmrid.reporting.decimate.MAX_POINTS` points).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from wmrid.core.errors import UsageError
from wmrid.reporting.convergence_figures import _display_scale, _finite
from wmrid.reporting.decimate import MAX_POINTS, envelope_indices
from wmrid.reporting.figures import (
    _LINE,
    _MEDIUM,
    _OUTWEIGH,
    _THICK,
    _WHEELS,
    FIGSIZE,
    FIGSIZE_STACKED,
    _legend_below,
    _new_figure,
    render,
)
from wmrid.reporting.svg import PX_PER_INCH, Figure
from wmrid.reporting.svg_style import RDBU_R, diverging, luminance

if TYPE_CHECKING:
    from wmrid.estimators.result import IdentificationResult


def _robust_limits(values: np.ndarray) -> tuple[float, float]:
    """Axis limits showing the bulk of ``values``: the full range, unless a few samples (the first
    steps' transient, a glitch) would squeeze the rest into a line; then the 0.5-99.5 % range, widened."""
    finite = values[np.isfinite(values)]
    if len(finite) == 0:
        return -1.0, 1.0
    lo, hi = float(finite.min()), float(finite.max())
    q_lo, q_hi = (float(q) for q in np.percentile(finite, [0.5, 99.5]))
    if hi - lo > 4.0 * (q_hi - q_lo):
        lo, hi = q_lo, q_hi
    lo, hi = min(lo, 0.0), max(hi, 0.0)
    pad = 0.08 * (hi - lo) if hi > lo else max(abs(hi), 1e-12)
    return lo - pad, hi + pad


def build_residuals_figure(result: IdentificationResult) -> Figure:
    """The prediction error e = eta - eta_hat (rad/s) over time for both wheels, and its histogram.

    Drawn from the recorded history (``result.history``, itself a subsample of the log).  When a few
    samples (typically the first steps, before the estimate has data) would squeeze the rest into a
    flat line, the axis shows the 0.5-99.5 % range and the samples beyond it are drawn as triangles
    at its edge, counted in the legend (the histogram counts only the samples within the axis).

    Parameters
    ----------
    result
        An identification with its history (t (n,) s, e (n, 2) rad/s).

    Returns
    -------
    Figure
        The errors over time (left, 3/4 of the width) and their distribution (right), sharing the error axis; the
        legend below.
    """
    h = result.history
    t = np.asarray(h.t, dtype=np.float64)
    e = np.asarray(h.e, dtype=np.float64)
    lo, hi = _robust_limits(e.ravel())
    scale, prefix = _display_scale(np.array([lo, hi]))
    lo, hi = lo / scale, hi / scale
    fig = _new_figure(left=0.9, top=0.35, bottom=0.85, gaps=(0.3, 0.0), grid=(1, 2), width_ratios=(3, 1), sharey=True)
    ax_t, ax_h = fig.panels
    bins = np.linspace(lo, hi, 61)
    beyond, extreme, most = 0, 0.0, 1
    for j, (wheel, colour) in enumerate(_WHEELS):
        col = e[:, j]
        ok = np.isfinite(col)
        rms = math.sqrt(float(np.mean(col[ok] ** 2))) if ok.any() else math.nan
        col = col / scale
        ax_t.line(t, col, color=colour, width=1.1, opacity=0.85, label=f"{wheel} wheel, RMS {rms:.3g} rad/s")
        inside = ok & (col >= lo) & (col <= hi)
        counts, _ = np.histogram(col[inside], bins=bins)
        most = max(most, int(counts.max(initial=0)))
        steps = np.concatenate([[0.0], np.repeat(counts, 2), [0.0]])  # the histogram's outline, as a step line
        ax_h.line(steps, np.repeat(bins, 2), color=colour, width=_MEDIUM, decimate=False)
        out = np.flatnonzero(ok & ~inside)
        if len(out):
            beyond += len(out)
            worst = scale * col[out[np.argmax(np.abs(col[out]))]]
            extreme = worst if abs(worst) > abs(extreme) else extreme
            keep = out[envelope_indices(col[out], MAX_POINTS)]
            for side, marker, edge in ((col[keep] > hi, "^", hi), (col[keep] < lo, "v", lo)):
                if side.any():
                    ax_t.markers(t[keep][side], np.full(side.sum(), edge), shape=marker, color=colour, size=7.0,
                                 clip=False)  # fmt: skip
    if beyond:
        ax_t.markers([], [], shape="^", color="0.4", size=7.0,
                     label=f"{beyond} samples beyond the axis (extreme {extreme:.3g} rad/s)")  # fmt: skip
    ax_t.set_ylim(lo, hi)
    ax_t.hline(0.0, color="k", width=0.8)
    ax_t.set_xlabel("time (s)")
    ax_t.set_ylabel(f"prediction error e = η − η̂ ({prefix}rad/s)")
    if len(t) > 1:
        ax_t.set_xlim(t[0], t[-1])
    ax_t.set_title("over time")
    ax_h.set_xlim(0.0, 1.05 * most)
    ax_h.set_xlabel("recorded samples (count)")
    ax_h.set_title("distribution")
    for ax in (ax_t, ax_h):
        ax.grid = "xy"
    _legend_below(fig, [ax_t])
    return fig


def residuals_figure(result: IdentificationResult, fmt: str = "svg") -> bytes:
    """:func:`build_residuals_figure` rendered as ``fmt`` bytes."""
    return render(build_residuals_figure(result), fmt)


# --------------------------------------------------------------------------------------------------
# 5. Excitation


def build_excitation_figure(result: IdentificationResult) -> Figure:
    """lambda_min(Gamma) over time on a log axis, against the start weight alpha.

    Gamma = alpha I + (the data's information), so lambda_min(Gamma) - alpha is the data's smallest
    eigenvalue, and on disturbance-free data the estimate keeps at most alpha / lambda_min(Gamma) of the
    start's error.  A vertical line marks when lambda_min(Gamma) first reaches 100 alpha (the data
    outweigh the start 100:1).  Gamma's entries mix the regressor columns' units, hence "mixed units".

    Parameters
    ----------
    result
        An identification with its history (t (n,) s, lambda_min (n,)) and its observer settings (alpha).

    Returns
    -------
    Figure
        One panel, log10 y axis (linear when nothing is positive), the legend below it (in a corner it covered the
        line of α, which runs the panel's width).
    """
    h = result.history
    t = np.asarray(h.t, dtype=np.float64)
    lam = np.asarray(h.lambda_min, dtype=np.float64)
    lam = np.where(np.isfinite(lam) & (lam > 0), lam, np.nan)
    alpha = float(result.observer_settings.alpha)
    fig = _new_figure(left=0.9, top=0.35, bottom=0.85)
    (ax,) = fig.panels
    ax.line(t, lam, color="C0", width=1.75, label="λ_min(Γ)")
    ax.hline(alpha, color="0.45", dash="--", width=1.33, label=f"α = {alpha:g} (weight of the start value)")
    reached = np.flatnonzero(lam >= _OUTWEIGH * alpha)
    texts = []
    if len(reached):
        t_x = t[reached[0]]
        ax.vline(t_x, color="C2", dash=":", width=_THICK,
                 label=f"λ_min ≥ {_OUTWEIGH:g} α from t = {t_x:.3g} s (data outweigh the start)")  # fmt: skip
    else:
        texts.append(f"λ_min never reaches {_OUTWEIGH:g} α: the start value still matters")
    if np.isfinite(lam).any():
        ax.y.scale = "log"
    ax.set_xlabel("time (s)")
    ax.set_ylabel("λ_min(Γ) (mixed units)")
    if len(t) > 1:
        ax.set_xlim(t[0], t[-1])
    ax.grid = "xy"
    _legend_below(fig, texts=texts)
    ax.set_title("smallest eigenvalue of the information matrix Γ")
    return fig


def excitation_figure(result: IdentificationResult, fmt: str = "svg") -> bytes:
    """:func:`build_excitation_figure` rendered as ``fmt`` bytes."""
    return render(build_excitation_figure(result), fmt)


# --------------------------------------------------------------------------------------------------
# 6. Base parameters over time


def _fit_text(fit: Any) -> str:
    v = _finite(fit)
    return f"{v:.3g} %" if math.isfinite(v) else "—"


def build_speed_fit_figure(
    t: np.ndarray | None, eta: np.ndarray | None, eta_hat: np.ndarray | None, fit: Any
) -> Figure | None:
    """Measured and model-predicted wheel speeds, right wheel above, left below; None when data are missing.

    The measured speed is drawn in the wheel's colour, the model's in black dashed.

    Parameters
    ----------
    t
        (n,) s.
    eta, eta_hat
        (n, 2) rad/s, measured and predicted (column 0 right, 1 left).
    fit
        (2,) percent, each panel's title ("—" when not finite); None: both unknown.

    Returns
    -------
    Figure or None
        Two panels sharing the time axis, the legend below; None when ``t``, ``eta`` or ``eta_hat`` is None.
    """
    if t is None or eta is None or eta_hat is None:
        return None
    t = np.asarray(t, dtype=np.float64)
    eta = np.asarray(eta, dtype=np.float64)
    eta_hat = np.asarray(eta_hat, dtype=np.float64)
    if t.ndim != 1 or eta.shape != (len(t), 2) or eta_hat.shape != eta.shape:
        raise UsageError(
            f"the speed fit needs t (n,), eta and eta_hat (n, 2), got {t.shape}, {eta.shape} and {eta_hat.shape}"
        )
    fits = [math.nan, math.nan] if fit is None else list(np.ravel(np.asarray(fit, dtype=object)))
    if len(fits) != 2:
        raise UsageError(f"the speed fit needs one fit per wheel (2,), got {len(fits)}")
    fig = _new_figure(FIGSIZE_STACKED, top=0.35, bottom=0.85, gaps=(0.0, 0.45), grid=(2, 1), sharex=True)
    for j, (wheel, colour) in enumerate(_WHEELS):
        ax = fig.panels[j]
        ax.line(t, eta[:, j], color=colour, width=_LINE, label=f"measured, {wheel} wheel")
        ax.line(t, eta_hat[:, j], color="k", dash="--", width=1.33, label="model")
        ax.set_title(f"{wheel} wheel: fit {_fit_text(fits[j])}")
        ax.set_ylabel("speed (rad/s)")
        ax.grid = "xy"
    fig.panels[1].set_xlabel("time (s)")
    if len(t) > 1:
        fig.panels[1].set_xlim(t[0], t[-1])
    measured = [e for e in fig.entries() if e[2].startswith("measured")]
    fig.legend_below([*measured, *[e for e in fig.entries() if e not in measured]])
    return fig


def speed_fit_figure(
    t: np.ndarray | None, eta: np.ndarray | None, eta_hat: np.ndarray | None, fit: Any, fmt: str = "svg"
) -> bytes | None:
    """:func:`build_speed_fit_figure` rendered as ``fmt`` bytes; None when data are missing."""
    fig = build_speed_fit_figure(t, eta, eta_hat, fit)
    return None if fig is None else render(fig, fmt)


# --------------------------------------------------------------------------------------------------
# 8. Correlations of the base parameters


def correlation_matrix(cov: Any) -> np.ndarray:
    """corr_ij = cov_ij / sqrt(cov_ii cov_jj) of a (k, k) covariance; NaN where undefined.

    An entry is undefined when it is None, NaN or infinite, or when either variance is (or is not > 0).
    """
    c = np.array([[_finite(v) for v in row] for row in cov], dtype=np.float64)
    if c.ndim != 2 or c.shape[0] != c.shape[1]:
        raise UsageError(f"a covariance must be square (k, k), got {c.shape}")
    d = np.diag(c).copy()
    ok = np.isfinite(d) & (d > 0.0)
    d[~ok] = math.nan
    with np.errstate(all="ignore"):
        return c / np.sqrt(np.outer(d, d))


def build_correlation_figure(names: Any, cov: Any) -> Figure | None:
    """The correlations of the base parameters as an annotated heat map with its colour scale.

    Colours from -1 (blue) through 0 (near white) to +1 (red) (ColorBrewer's RdBu, reversed); each cell shows its value,
    white on dark cells; undefined cells are grey and marked "—".

    Parameters
    ----------
    names
        (k,) parameter names.
    cov
        (k, k) their covariance; None, NaN or infinite where undefined.

    Returns
    -------
    Figure or None
        Square cells, the first parameter at the top left, the colour bar at the right; None when k < 2.
    """
    names = [str(n) for n in names]
    k = len(names)
    if k < 2:
        return None
    corr = correlation_matrix(cov)
    if corr.shape != (k, k):
        raise UsageError(f"a covariance of {k} parameters must be ({k}, {k}), got {corr.shape}")
    size = (FIGSIZE[0], max(FIGSIZE[1], 0.5 * k + 1.6))
    fig = _new_figure(size, left=3.0, right=2.6, top=0.2, bottom=0.6)
    (ax,) = fig.panels
    left, top, w, h = ax.box
    side = min(w, h)
    ax.box = (left + (w - side) / 2, top, side, side)  # square cells
    fills = [[diverging(float(v)) for v in row] for row in corr]
    ax.cells(fills)
    for i in range(k):
        for j in range(k):
            v = corr[i, j]
            if math.isfinite(v):
                colour = "white" if luminance(fills[i][j]) < 0.5 else "black"
                text = f"{v:.2f}".replace("-", "−").replace("−0.00", "0.00")
            else:
                colour, text = "black", "—"
            ax.text(j, i, text, color=colour)
    ax.set_xlim(-0.5, k - 0.5)
    ax.set_ylim(k - 0.5, -0.5)  # first parameter at the top
    ax.x.ticks = ax.y.ticks = (list(range(k)), names)
    ax.x.tick_length = ax.y.tick_length = 0.0
    bar = fig.add_panel((ax.box[0] + side + 0.25 * PX_PER_INCH, top, 0.2 * PX_PER_INCH, side))
    bar.gradient([(n / (len(RDBU_R) - 1), c) for n, c in enumerate(RDBU_R)])
    bar.set_ylim(-1.0, 1.0)
    bar.y.side = "right"
    bar.x.ticks = ([], [])
    bar.set_ylabel("correlation")
    return fig


def correlation_figure(names: Any, cov: Any, fmt: str = "svg") -> bytes | None:
    """:func:`build_correlation_figure` rendered as ``fmt`` bytes; None when fewer than 2 names."""
    fig = build_correlation_figure(names, cov)
    return None if fig is None else render(fig, fmt)
