"""The terminal view of ``wmrid export``: what was written, the physical quantities (what the log determines, what the
robot file gives, what stays undetermined) and the check's fit."""

from __future__ import annotations

import math
from typing import Any

from wmrid.estimators.diagnostics import POORLY_DETERMINED as POORLY
from wmrid.reporting.terminal import print_table


def print_export(data: dict[str, Any], console: Any) -> None:
    """Render an export's JSON (:meth:`wmrid.api.exporting.ExportResult.to_dict`) on ``console``."""
    console.print(f"Wrote {data['format']} to {data['path']}.")
    for note in data.get("notes", []):
        console.print(f"Note: {note}.")
    console.print()
    if data["physical"] is None:
        return
    rows = []
    for name, q in data["physical"]["quantities"].items():
        std = q["std"]
        if q["source"] == "robot file":
            continue
        if std is None:
            mark = "undetermined"
        elif q["value"] != 0 and std > POORLY * abs(q["value"]):
            mark = "poorly"
        else:
            mark = "yes"
        rel = f"{100 * std / abs(q['value']):.2g} %" if std is not None and q["value"] else "-"
        source = "log+file" if q["source"] == "log + robot file" else q["source"]
        rows.append([name, f"{q['value']:.5g}", "-" if std is None else f"{std:.2g}", rel, q["unit"], source,
                     mark])  # fmt: skip
    print_table(console, ["quantity", "value", "std", "relative", "unit", "from", "determined"], rows,
                title="Physical quantities (from: the log, or the log with the robot file's geometry)",
                numeric=(1, 2, 3))  # fmt: skip
    console.print(
        "m: total mass; I: yaw inertia about the axle midpoint O; mp_dy, mp_dx: the first moments m_p d_y and "
        "m_p d_x + 2 m_r c_x; m_p, d_x, d_y, I_p: the platform's mass, centre of mass and yaw inertia about it."
    )
    given = [n for n, q in data["physical"]["quantities"].items() if q["source"] == "robot file"]
    console.print(f"From the robot file, taken as known: {', '.join(given)}.")
    console.print(f"Not determined by a wheel log: {'; '.join(data['physical']['undetermined'])}.")
    check = data.get("check")
    if check:

        def fmt(v: float | None) -> str:
            return "-" if v is None or not math.isfinite(v) else f"{v:.2f} %"

        console.print()
        rows = [[model, fmt(check[model]["eta_r"]), fmt(check[model]["eta_l"])] for model in ("multibody", "reduced")]
        print_table(console, ["model", "fit right", "fit left"], rows,
                    title=f"Check on {check['log']} ({check['windows']} windows of {check['window_s']:g} s)",
                    numeric=(1, 2))  # fmt: skip
        if check.get("reduced_not_simulated"):
            console.print(f"The reduced model: {check['reduced_not_simulated']}.")
