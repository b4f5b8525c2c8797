"""The terminal view of ``wmrid export``: what was written, the physical quantities (what the log determines, what the
robot file gives, what stays undetermined) and the check's fit, read from the typed
:class:`~wmrid.model.export_result.ExportResult`."""

from __future__ import annotations

import math
from typing import Any

from wmrid.estimators.diagnostics import POORLY_DETERMINED as POORLY
from wmrid.model.export_result import ExportResult
from wmrid.reporting.terminal import print_table


def print_export(result: ExportResult, console: Any) -> None:
    """Render what :func:`wmrid.api.exporting.export` wrote on ``console``."""
    console.print(f"Wrote {result.format} to {result.path}.")
    for note in result.notes:
        console.print(f"Note: {note}.")
    console.print()
    physical = result.physical
    if physical is None:
        return
    rows = []
    for name, q in physical.quantities.items():
        if q.source == "robot file":
            continue
        known = math.isfinite(q.std)
        if not known:
            mark = "undetermined"
        elif q.value != 0 and q.std > POORLY * abs(q.value):
            mark = "poorly"
        else:
            mark = "yes"
        rel = f"{100 * q.std / abs(q.value):.2g} %" if known and q.value else "-"
        source = "log+file" if q.source == "log + robot file" else q.source
        rows.append([name, f"{q.value:.5g}", f"{q.std:.2g}" if known else "-", rel, q.unit, source, mark])
    print_table(console, ["quantity", "value", "std", "relative", "unit", "from", "determined"], rows,
                title="Physical quantities (from: the log, or the log with the robot file's geometry)",
                numeric=(1, 2, 3))  # fmt: skip
    console.print(
        "m: total mass; I: yaw inertia about the axle midpoint O; mp_dy, mp_dx: the first moments m_p d_y and "
        "m_p d_x + 2 m_r c_x; m_p, d_x, d_y, I_p: the platform's mass, centre of mass and yaw inertia about it."
    )
    given = [name for name, q in physical.quantities.items() if q.source == "robot file"]
    console.print(f"From the robot file, taken as known: {', '.join(given)}.")
    console.print(f"Not determined by a wheel log: {'; '.join(physical.undetermined)}.")
    check = result.check
    if check is not None:

        def fmt(v: float | None) -> str:
            return "-" if v is None or not math.isfinite(v) else f"{v:.2f} %"

        console.print()
        rows = [[model, fmt(fit["eta_r"]), fmt(fit["eta_l"])] for model, fit in check.fits()]
        print_table(console, ["model", "fit right", "fit left"], rows,
                    title=f"Check on {check.log} ({check.windows} windows of {check.window_s:g} s)",
                    numeric=(1, 2))  # fmt: skip
        if check.reduced_not_simulated:
            console.print(f"The reduced model: {check.reduced_not_simulated}.")
