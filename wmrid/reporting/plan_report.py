"""``wmrid report plan.json -o plan.html``: a plan on one page -- the verdict, the planned path inside the area, the
reference and the wheels' speeds, accelerations and torques against their limits over time, and the predicted std
of each parameter next to the baselines'.  Self-contained HTML (inline SVG), or Markdown without the figures."""

from __future__ import annotations

import html
from typing import Any

import numpy as np

from wmrid.design.excitation import wheel_motion
from wmrid.design.plan import Plan
from wmrid.model.torques import wheel_torque
from wmrid.reporting import markdown as md
from wmrid.reporting.decimate import MAX_POINTS, envelope_indices
from wmrid.reporting.figures import _LINE, _MEDIUM, FIGSIZE, FIGSIZE_STACKED, _legend_below, _new_figure, render
from wmrid.reporting.plan_view import BASELINE_TEXT, summary
from wmrid.reporting.report_table import ReportTable
from wmrid.reporting.svg import Figure


def plan_figures(plan: Plan) -> dict[str, Figure]:
    """The plan's figures by caption: the path, the reference (v, w), the wheel speeds, accelerations and torques
    with their limits (dashed: the limit; dotted: the plan's bound after the margin), the predicted relative std.

    Parameters
    ----------
    plan
        A designed plan (:func:`wmrid.design.plan.design_plan`).

    Returns
    -------
    dict of str to Figure
        Caption -> figure (:mod:`wmrid.reporting.svg`), in the page's order.
    """
    s = plan.samples(max(plan.settings.rate, 50.0))
    t = s.t
    v, w, dv, dw = plan.excitation.evaluate(t)
    eta, deta = wheel_motion(v, w, dv, dw, plan.r, plan.b)
    theta0 = np.array([p.nominal for p in plan.predicted.values()])
    tau = wheel_torque(eta, deta, theta0, plan.form) if plan.form.geometry else wheel_torque(eta, deta, theta0[:8])
    lim = plan.limits
    keep = 1.0 - lim.margin
    out: dict[str, Figure] = {}

    fig = _new_figure(FIGSIZE)
    (ax,) = fig.panels
    wx, wy = lim.area[0] / 2.0, lim.area[1] / 2.0
    ax.line([-wx, wx, wx, -wx, -wx], [-wy, -wy, wy, wy, -wy], color="k", dash="--", width=1.33, label="area")
    bx, by = wx - lim.footprint, wy - lim.footprint
    ax.line([-bx, bx, bx, -bx, -bx], [-by, -by, by, by, -by], color="k", dash=":", width=1.33,
            label="axle midpoint's room (robot's reach)")  # fmt: skip
    half = MAX_POINTS // 2
    idx = np.union1d(envelope_indices(np.asarray(s.x), half), envelope_indices(np.asarray(s.y), half))
    ax.line(np.asarray(s.x)[idx], np.asarray(s.y)[idx], color="C0", width=_MEDIUM, label="planned path",
            decimate=False)  # fmt: skip
    ax.markers(0.0, 0.0, shape="o", color="C2", size=10.0, label="start (facing +x)")
    ax.markers(s.x[-1], s.y[-1], shape="s", color="C3", size=9.0, label="end")
    ax.equal = True
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid = "xy"
    ax.legend("best")
    out["Planned path inside the area"] = fig

    fig = _new_figure(FIGSIZE_STACKED, gaps=(0.0, 0.15), grid=(2, 1), sharex=True)
    ax1, ax2 = fig.panels
    ax1.line(t, v, color="C0", width=_LINE)
    ax1.set_ylabel("v (m/s)")
    ax2.line(t, w, color="C4", width=_LINE)
    ax2.set_ylabel("omega (rad/s)")
    for ax, value in ((ax1, lim.max_speed), (ax2, lim.max_turn_rate)):
        if value is not None:
            for sign in (1, -1):
                ax.hline(sign * value, color="k", dash="--", width=1.1)
        ax.grid = "xy"
    ax2.set_xlabel("t (s)")
    out["Reference: forward speed and turn rate"] = fig

    for caption, data, value, unit in (
        ("Wheel speeds against their limit", eta, lim.max_wheel_speed, "rad/s"),
        ("Wheel accelerations against their limit", deta, lim.max_wheel_accel, "rad/s^2"),
        ("Wheel torques (nominal model) against their limit", tau, lim.max_torque, "N m"),
    ):
        fig = _new_figure(FIGSIZE, bottom=0.85)
        (ax,) = fig.panels
        ax.line(t, data[:, 0], color="C0", width=1.33, label="right")
        ax.line(t, data[:, 1], color="C1", width=1.33, label="left")
        if value is not None:
            for sign in (1, -1):
                ax.hline(sign * value, color="k", dash="--", width=1.1, label="limit")
                ax.hline(sign * keep * value, color="k", dash=":", width=1.1, label="planned bound")
        ax.set_xlabel("t (s)")
        ax.set_ylabel(unit)
        ax.grid = "xy"
        _legend_below(fig)
        out[caption] = fig

    fig = _new_figure(FIGSIZE, bottom=0.85)
    (ax,) = fig.panels
    names = list(plan.predicted)
    x = np.arange(len(names))
    width = 0.8 / (1 + len(plan.baselines))
    ax.bars(x, [100 * plan.predicted[n].relative for n in names], width=width, colors="C2", label="this plan")
    for i, (name, base) in enumerate(plan.baselines.items()):
        # a parameter the baseline's log cannot determine (None, or inf in memory) has no bar
        relative = base.relative or {}
        values = [100 * v if v is not None and np.isfinite(v) else np.nan for v in map(relative.get, names)]
        ax.bars(x + (i + 1) * width, values, width=width, colors=f"C{i}", label=BASELINE_TEXT.get(name, name))
    ax.y.scale = "log"
    ax.x.ticks = ((x + 0.4 - width / 2).tolist(), names)
    ax.set_ylabel("predicted std, % of scale")
    ax.grid = "y"
    _legend_below(fig)
    out["Predicted relative std: this plan and the baselines (same duration and limits)"] = fig
    return out


_CSS = (
    "body{font-family:system-ui,sans-serif;max-width:1100px;margin:1em auto;padding:0 1em;color:#222}"
    "table{border-collapse:collapse;margin:.5em 0}td,th{padding:.2em .6em;border-bottom:1px solid #ddd;"
    "text-align:right;white-space:nowrap}td:first-child,th:first-child{text-align:left}"
    ".scroll{overflow-x:auto}figure{margin:1em 0}figure svg{width:100%;height:auto}"
    "figcaption{font-weight:600;margin-bottom:.3em}.small{color:#555}"
)


def tables(plan: Plan) -> dict[str, ReportTable]:
    """The plan's tables: title -> :class:`ReportTable` (the predicted precision beside the baselines', the limits
    and the plan's use of each)."""
    baselines = plan.baselines
    predicted = ReportTable(
        header=["parameter", "nominal", "predicted std", "relative", "scale",
                *[f"{b} (relative)" for b in baselines]],
        rows=[[name, f"{p.nominal:.4g}", f"{p.std:.3g}", f"{100 * p.relative:.3g} %", f"{p.scale:.3g} ({p.scale_from})",
               *[_pct((base.relative or {}).get(name)) for base in baselines.values()]]
              for name, p in plan.predicted.items()],
    )  # fmt: skip
    limits = ReportTable(
        header=["limit", "value", "unit", "plan's peak", "share of the limit", "from"],
        rows=[[name, f"{u.limit:.3g}", u.unit, f"{u.peak:.3g}", f"{100 * u.share:.0f} %",
               plan.limits.sources.get("area" if name.startswith("area") else name, "-")]
              for name, u in plan.limits_used.items() if u.limit is not None],
    )  # fmt: skip
    return {"Predicted precision": predicted, "Limits": limits}


def _pct(x: Any) -> str:
    return "-" if x is None else f"{100 * x:.3g} %"


def to_html(plan: Plan) -> str:
    """One self-contained page (inline SVG, inline style, nothing fetched)."""
    settings = plan.settings
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        "<meta name='viewport' content='width=device-width, initial-scale=1'>",
        f"<title>wmrid plan: {html.escape(plan.robot)}</title><style>{_CSS}</style></head><body>",
        f"<header><h1>wmrid plan</h1><p class='small'>robot {html.escape(plan.robot)}, "
        f"{settings.duration:g} s, seed {settings.seed}</p>",
        "<section class='verdict'>" + "".join(f"<p><strong>{html.escape(s)}</strong></p>" for s in summary(plan)),
        "</section></header>",
    ]
    for title, table in tables(plan).items():
        head = "".join(f"<th>{html.escape(str(h))}</th>" for h in table.header)
        body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>"
                       for row in table.rows)  # fmt: skip
        parts.append(f"<h2>{html.escape(title)}</h2><div class='scroll'><table><thead><tr>{head}</tr></thead>"
                     f"<tbody>{body}</tbody></table></div>")  # fmt: skip
    parts.append("<h2>Figures</h2>")
    for caption, fig in plan_figures(plan).items():
        text = render(fig, "svg").decode("utf-8")
        text = text[text.index("<svg") :]
        parts.append(f"<figure><figcaption>{html.escape(caption)}</figcaption>{text}</figure>")
    notes = [*plan.warnings]
    noise = plan.noise
    source = "given" if settings.noise_source is None else settings.noise_source
    notes.append(
        f"The prediction assumes white noise of {noise.eta_std:.3g} rad/s and {noise.tau_std:.3g} N m per sample "
        f"at {noise.rate:g} Hz ({source}), a robot that tracks the reference "
        f"on its nominal model, and identification with wmrid's observer fitting the {settings.friction} "
        "friction model; a coloured disturbance (a rough floor, slip) or a controller that reacts to the noise make "
        "the achieved std larger."
    )
    parts += ["<h2>Notes</h2><ul>", *[f"<li>{html.escape(n)}</li>" for n in notes], "</ul></body></html>"]
    return "\n".join(parts)


def to_markdown(plan: Plan) -> str:
    """The plan as Markdown; the robot's name, the tables' cells and the warnings escaped
    (:mod:`wmrid.reporting.markdown`)."""
    lines = [f"# wmrid plan: {md.text(plan.robot, False)}", "", *[md.text(s) for s in summary(plan)], ""]
    for title, table in tables(plan).items():
        lines += [f"## {md.text(title)}", "", md.table(table.header, table.rows), ""]
    lines += [f"- {md.text(w)}" for w in plan.warnings]
    return "\n".join(lines) + "\n"
