"""``wmrid monitor`` for people: the changes found, and the parameters before and after each, as rich tables (read
from the typed :class:`~wmrid.monitoring.monitor_result.MonitorResult`: its model's and each change's parameters are
:class:`~wmrid.estimators.parameter.Parameter`)."""

from __future__ import annotations

import math
from typing import Any

from wmrid.model import dynamics as model
from wmrid.model.dynamics import THETA0_NAMES
from wmrid.monitoring.monitor_result import MonitorResult
from wmrid.reporting.terminal import print_table, warning


def _fmt(x: Any, digits: int = 6) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    return f"{x:.{digits}g}"


def print_monitor(result: MonitorResult, console: Any) -> None:
    """The changes found, and the parameters before and after each, as rich tables."""
    first, limit = result.thresholds
    st = result.settings
    console.print(f"wmrid monitor: {result.source} against {result.model.source}")
    info = result.log_info
    console.print(
        f"{info.samples} samples, {info.duration_s:.3f} s at {info.rate_hz:.6g} Hz; windowed GLR test of "
        f"the torque residual, at most {st.false_alarm_rate:g} false alarms per hour (threshold "
        f"{first:.4g} after the first {st.calibration_s:g} s, assumed unchanged, "
        f"falling to {limit:.4g} as the calibration grows)"
    )
    if not result.changes:
        console.print("no change of the dynamics detected")
    else:
        rows = [[str(i), f"{c.t:.3f}", f"{c.t_alarm:.3f}", f"{c.t_alarm - c.t:.3f}", f"{c.statistic:.4g}",
                 f"{c.threshold:.4g}", f"{c.window_s:.3g}"] for i, c in enumerate(result.changes, 1)]  # fmt: skip
        print_table(console, ["#", "t s", "alarm s", "delay s", "statistic", "threshold", "window s"], rows,
                    title="changes of the dynamics", numeric=tuple(range(7)))  # fmt: skip
        header = ["param", "model"]
        for i in range(len(result.changes)):
            header += [f"after #{i + 1}", "std"]
        header.append("unit")
        units = model.base_units(result.model.effort_unit)
        drag = list(dict.fromkeys(name for params in [result.model.parameters, *(c.parameters or {} for c in
                                  result.changes)] for name in params if name in units and name not in
                                  (*THETA0_NAMES, "M11", "M12", "M22")))  # fmt: skip
        rows = []
        for name in (*THETA0_NAMES[:3], "M11", "M12", "M22", *THETA0_NAMES[3:], *drag):
            given = result.model.parameters.get(name)
            row = [name, _fmt(None if given is None else given.value)]
            for c in result.changes:
                after = (c.parameters or {}).get(name)
                row += ["-", "-"] if after is None else [_fmt(after.value), _fmt(after.std, 2)]
            rows.append([*row, units.get(name, "")])
        print_table(console, header, rows, title="parameters before and after each change",
                    numeric=tuple(range(1, len(header) - 1)))  # fmt: skip
    for note in info.notes:
        console.print(f"note: {note}")
    for c in result.changes:
        for w in c.warnings:
            console.print(warning(f"after the change at {c.t:.3f} s: {w}"))
    for w in result.warnings:
        console.print(warning(w))
