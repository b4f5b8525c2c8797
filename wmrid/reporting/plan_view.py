"""A plan in the terminal: the verdict first (what the drive is predicted to determine, against the baselines), then
the predicted std per parameter, the limits and how close the plan comes to each, what it assumes."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from wmrid.design.plan import Plan
from wmrid.model.dynamics import THETA0_UNITS
from wmrid.reporting.terminal import print_table, warning

BASELINE_TEXT = {"sinusoid": "the paper's sinusoid", "reversing": "the back-and-forth drive (reversing)"}


#: How the prediction held, said with every plan (docs/explanation/plan.md, "Measured").
PREDICTION_ACCURACY = (
    "On simulated logs of plans (bench/studies/study_plan.py) the std wmrid identify reported came out 0.9-1.6 times "
    "the prediction (median per parameter)."
)


def _times(x: float | None) -> str:
    if x is None or x != x:
        return "-"
    if x == float("inf"):
        return "infinitely"
    return f"{x:.3g}x" if x < 100 else f"{x:.0f}x"


def _or_one(x: float | None) -> float:
    return 1.0 if x is None else x


def summary(plan: Plan) -> list[str]:
    """The plan's verdict in plain sentences (the first lines of every rendering)."""
    crit = plan.criterion
    worst = plan.predicted[plan.worst]
    lines = [
        f"This {plan.settings.duration:g} s drive is predicted to determine every base parameter of {plan.robot} to "
        f"{100 * worst.relative:.3g} % of its scale or better (worst: {crit.worst}, std "
        f"{worst.std:.3g} {THETA0_UNITS.get(plan.worst, '')})."
    ]
    parts = []
    for name, base in plan.baselines.items():
        text = f"{_times(base.improvement)} better than {BASELINE_TEXT.get(name, name)}"
        slowed = _or_one(base.slowed_by)
        if slowed < 0.999:
            text += f" (slowed to {100 * slowed:.0f} % to keep the limits"
            open_floor = base.area_ignored
            if open_floor is not None and _or_one(open_floor.slowed_by) > slowed + 1e-9:
                text += f"; on an open floor {_times(open_floor.improvement)}"
            text += ")"
        parts.append(text)
    if parts:
        lines.append("Within the same limits and time: " + "; ".join(parts) + ".")
    aside = [(n, p) for n, p in plan.predicted.items() if not p.in_criterion]
    if aside:
        lines.append(
            "How the casters' drag follows their load ("
            + ", ".join(f"{n} {100 * p.relative:.3g} %" for n, p in aside)
            + ") is predicted too, but not counted: it describes the drag's change, not the robot."
        )
    if crit.name != "worst":
        lines.append(f"Criterion: {crit.text}, {100 * crit.value:.3g} %.")
    return lines


def print_plan(plan: Plan, console: Any, written: Sequence[str] = ()) -> None:
    """Render a plan (:class:`wmrid.design.plan.Plan`) on ``console``; ``written``: the files it was written to."""
    for line in summary(plan):
        console.print(line)
    console.print()
    rows = []
    for name, p in plan.predicted.items():
        unit = THETA0_UNITS.get(name, "")
        scale_from = "nominal" if p.scale_from == "nominal value" else "floor"
        rows.append([name, f"{p.nominal:.4g}", f"{p.std:.2g}", f"{100 * p.relative:.3g} %",
                     f"{p.scale:.3g} ({scale_from})", unit])  # fmt: skip
    print_table(console, ["parameter", "nominal", "predicted std", "relative", "scale", "unit"], rows,
                title="Predicted precision", numeric=(1, 2, 3))  # fmt: skip
    console.print()
    lim = plan.limits
    rows = []
    for name, used in plan.limits_used.items():
        if used.limit is None:
            continue
        key = "area" if name.startswith("area") else name
        rows.append([name, f"{used.limit:.3g} {used.unit}", f"{used.peak:.3g}", f"{100 * used.share:.0f} %",
                     lim.sources.get(key, "-")])  # fmt: skip
    print_table(console, ["limit", "value", "plan's peak", "share", "from"], rows,
                title=f"Limits (planned to {100 * (1 - lim.margin):.0f} % of each)", numeric=(1, 2, 3))  # fmt: skip
    m = plan.margins
    console.print()
    wheels = "; ".join(
        f"{w} wheel forward {100 * spread.forward_share:.0f} % and backward {100 * spread.backward_share:.0f} % of "
        f"the time, at {spread.speed_percentiles[0]:.2g}-{spread.speed_percentiles[2]:.2g} rad/s"
        for w, spread in (("right", m.right), ("left", m.left))
    )
    console.print(f"Separable: {wheels}; corr(v, w) = {m.corr_v_w:.2f}.")
    noise = plan.noise
    s = plan.settings
    source = "given" if s.noise_source is None else s.noise_source
    console.print(
        f"Assumes: noise {noise.eta_std:.3g} rad/s and {noise.tau_std:.3g} N m per sample at {noise.rate:g} Hz"
        " "
        f"({source}); the robot tracks the reference on its nominal model (wmrid simulate's "
        f"controller); identification with the observer (k = {s.k:g} 1/s), friction model {s.friction}. "
        f"{PREDICTION_ACCURACY}"
    )
    if plan.given is not None and plan.given.results:
        sources = [g.source for g in plan.given.results]
        console.print(
            f"Adds the information of: {', '.join(sources)}. The std predicted are those of wmrid identify LOG "
            f"--given {' --given '.join(sources)} on the planned drive's log."
        )
    for text in plan.warnings:
        console.print(warning(text))
    for path in written:
        console.print(f"wrote {path}")
