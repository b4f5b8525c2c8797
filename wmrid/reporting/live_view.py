"""The terminal view of ``wmrid live``: estimate ± std per parameter with its trend, and the stream's state.

Reads the typed records a live run yields: :class:`~wmrid.estimators.observer.live_update.LiveUpdate` and
:class:`~wmrid.monitoring.live_change.LiveChange` (both below this layer).
"""

from __future__ import annotations

import json
import math
from typing import Any

from wmrid.estimators.observer.live_update import LiveUpdate
from wmrid.monitoring.live_change import LiveChange
from wmrid.runtime.atomic import _jsonable

#: Parameters shown, in order (those the update has).
SHOWN = ("m11", "m12", "m22", "M11", "M12", "M22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")


def _trend(now: float, before: float | None, std: float) -> str:
    """An arrow when the value moved by more than its std since the last update, else a dot (nothing when there is
    no value before or the std is not finite)."""
    if before is None or not math.isfinite(std):
        return ""
    if abs(now - before) <= std:
        return "·"
    return "↑" if now > before else "↓"


def live_table(update: LiveUpdate, previous: LiveUpdate | None = None) -> Any:
    """A rich renderable: a header line (source, samples, rates, log time, time since the last data, form) and a table
    of each parameter's estimate, std, relative std and trend since ``previous``."""
    from rich.console import Group  # rich (~20 ms): only the live table on a terminal
    from rich.table import Table  # rich: only the live table on a terminal
    from rich.text import Text  # rich: only the live table on a terminal

    log_rate = update.log_rate_hz
    head = Text(
        f"{update.source}: {update.samples:,} samples, {update.log_time_s:.1f} s of log"
        + (f" at {log_rate:.0f} Hz" if log_rate else "")
        + f"; receiving {update.rate_hz:.0f} samples/s; last data {update.since_last_data_s:.1f} s ago"
        + (f"; form {update.form}" if update.form else "")
    )
    table = Table(box=None, pad_edge=False)
    for col, justify in (("parameter", "left"), ("estimate", "right"), ("± std", "right"), ("rel. std", "right"),
                         ("trend", "center")):  # fmt: skip
        table.add_column(col, justify=justify)  # type: ignore[arg-type]
    params = update.parameters
    before = previous.parameters if previous is not None else {}
    if not params:
        table.add_row("(waiting for enough samples)", "", "", "", "")
    for name in SHOWN:
        if name not in params:
            continue
        value, std = params[name]
        known = math.isfinite(std)
        rel = f"{100 * std / abs(value):.3g} %" if known and value else ""
        old = before[name][0] if name in before else None
        table.add_row(name, f"{value:.6g}", f"{std:.3g}" if known else "?", rel, _trend(value, old, std))
    foot = Text("std: jackknife of the live estimate (the final result carries the offline std)", style="dim")
    parts = [head, table, foot]
    parts += [Text(f"note: {n}", style="dim") for n in update.notes]
    return Group(*parts)


def change_line(change: LiveChange) -> Any:
    """A highlighted line for a change found along the stream."""
    from rich.text import Text  # rich (~15 ms): only a change line on a terminal

    moved = ", ".join(f"{n} {before:.4g} → {after:.4g}" for n, (before, after, _) in change.moved.items())
    text = (
        f"CHANGE at {change.t:.2f} s ({change.kind}; alarm at {change.t_alarm:.2f} s, raised at "
        f"{change.t_raised:.2f} s of log): {moved or 'no term alone'}"
    )
    if change.payload is not None:
        text += f"; payload {change.payload.mass:.3g} ± {change.payload.std:.2g} kg (from {change.fit_s:.1f} s)"
    return Text(text, style="bold reverse red")


def json_line(obj: Any) -> str:
    """``obj`` as one line of strict JSON (NaN/inf as null), without the newline: a JSON-lines record."""
    return json.dumps(_jsonable(obj), allow_nan=False, separators=(",", ":"))
