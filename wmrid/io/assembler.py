"""Columns of a table or a bag's messages assembled into the wheel signals piece by piece (:class:`Assembler`): the
canonical columns checked, speeds from positions, efforts converted, pieces merged on one time base."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from wmrid.core.errors import LogFormatError, option
from wmrid.core.wheel_log import (
    MIN_SAMPLES,
    POSE,
    POSITION,
    REFERENCE,
    REQUIRED,
    WheelLog,
)
from wmrid.io.stamps import (
    ABSOLUTE_LIMIT_S,
    EPOCH_LIKE_S,
    MIN_PLAUSIBLE_STEP_S,
    PER_SECOND,
    implausible_step,
    seconds,
)

#: The time column of PlotJuggler's CSV export, which merges every topic's samples into one table.
MERGED_TIME = "__time"


def _numeric(values: Any, key: str, col: str, name: str, where: Callable[[int], str]) -> np.ndarray:
    """A numeric numpy array (int or float) or a LogFormatError naming the first non-numeric cell."""
    if isinstance(values, np.ndarray) and values.dtype.kind in "iuf":
        return values
    import pandas as pd  # only for non-numeric columns: keeps a numeric Parquet read free of pandas

    series = pd.Series(values)
    if series.dtype.kind == "b":
        raise LogFormatError(f"{name}: column {col!r} holds true/false values; map {key} to a numeric column")
    coerced = pd.to_numeric(series, errors="coerce")
    bad = coerced.isna().to_numpy() & series.notna().to_numpy()
    if bad.any():
        i = int(np.argmax(bad))
        raise LogFormatError(
            f"{name}: {where(i)}, column {col!r}: {str(series.iloc[i])[:40]!r} is not a number; fix or delete that row"
        )
    out = coerced.to_numpy()
    return out if out.dtype.kind in "iuf" else out.astype(np.float64)


def _first_nonfinite(arr: np.ndarray) -> int | None:
    """Index of the first NaN/inf in ``arr`` (None if all finite or not floating point)."""
    if arr.dtype.kind != "f":
        return None
    ok = np.isfinite(arr)
    return None if ok.all() else int(np.argmin(ok))


def _nonfinite_message(arr: np.ndarray, i: int, col: str, name: str, where: Callable[[int], str]) -> str:
    what = "empty or NaN" if np.isnan(arr[i]) else f"{float(arr[i])}"
    return f"{name}: {where(i)}, column {col!r} is {what}; fill or delete that row"


class Assembler:
    """Turns the columns of successive pieces of a table log into :class:`WheelLog` pieces.

    Checks each piece as :func:`read_log` checks a whole log (numbers, finite, time strictly increasing,
    also across pieces) and makes the log-wide decisions (time unit, offset, epoch-like stamps) on the
    first piece that has rows.  ``finish()`` returns the notes and raises for a log too short to use.
    """

    def __init__(
        self, name: str, mapping: dict[str, str], time_unit: str, hint: str | None, where: Callable[[int], str],
        reference_required: bool = False, merged: bool = False,
    ):  # fmt: skip
        self.name, self.mapping, self.time_unit, self.hint, self.where = name, mapping, time_unit, hint, where
        self.merged = merged  # a merged export (PlotJuggler): rows without any wheel value are other topics'
        self.empty_rows = 0
        self.empty_first: str | None = None
        self.reference_required = reference_required  # named by --columns: a bad cell is an error, not a note
        self.notes: list[str] = []
        self.unit: str | None = None
        self.kind: str | None = None  # "i" or "f": the time column's kind in the first piece
        self.offset: int | float | None = None
        self.epoch: bool | None = None  # whether stamps are epoch times (zero stamps are then dropped)
        self.zero_rows = 0
        self.zero_first: str | None = None
        self.held_zeros = 0  # leading all-zero rows not yet known to be bad epoch stamps
        self.held_first: str | None = None
        self.prev_stamp: Any = None
        self.prev_t: float | None = None
        self.first_step: float | None = None
        self.first_stamp = 0.0  # the first stamp as stored (for the message about an implausible unit)
        self.first_t = 0.0
        self.n = 0
        self.dropped: set[str] = set()  # optional column groups dropped for the rest of the log (_optional)
        self.last_t = 0.0
        self.positions = False  # the wheel columns are positions (pos_r, pos_l), not speeds
        self.required = REQUIRED

    def add(self, values: dict[str, Any], base: int) -> WheelLog | None:
        """The piece whose first row is data row ``base`` (0-based) of the file, or None if it has no rows left.

        ``values`` holds the columns :func:`wmrid.io.table.columns.select` chose: with wheel positions (pos_r, pos_l) in
        place of the speeds, the piece's ``eta`` holds those positions, as read, for the caller to differentiate.
        """
        name, mapping = self.name, self.mapping
        self.positions = POSITION[0] in values
        self.required = REQUIRED if not self.positions else ("t", *POSITION, "tau_r", "tau_l")
        required = self.required
        kept = None

        def where(i: int) -> str:
            return self.where(base + (int(kept[i]) if kept is not None else i))

        arrays = {key: _numeric(values[key], key, mapping[key], name, where) for key in required}
        if self.merged:
            arrays, values, kept = self._other_topics(arrays, values, where)
            if not len(arrays["t"]):
                return None
        bad = [(i, key) for key in required if (i := _first_nonfinite(arrays[key])) is not None]
        if bad:  # the first non-finite cell in file order among the required columns
            i, key = min(bad, key=lambda b: (b[0], required.index(b[1])))
            raise LogFormatError(_nonfinite_message(arrays[key], i, mapping[key], name, where))
        stamps = self._stamps(arrays["t"], where)

        zero = stamps == 0
        if self.epoch is None and self.n == 0 and len(zero) > 1 and zero.all():
            # undecided: hold the zero rows back until a stamp says whether they are a clock not yet set
            self.held_zeros += len(zero)
            self.held_first = self.held_first or where(0)
            return None
        if self.epoch is None and not zero.all():  # decided by the first piece with a non-zero stamp
            self.epoch = bool(np.min(np.abs(stamps[~zero])) > EPOCH_LIKE_S)
            if self.held_zeros and self.epoch:
                self.zero_rows += self.held_zeros
                self.zero_first = self.held_first
                self.held_zeros = 0
            elif self.held_zeros:  # zeros, then times that are not epoch times: time stood still
                raise LogFormatError(
                    f"{name}: time is not strictly increasing at {self.held_first}: the log starts with "
                    f"{self.held_zeros} rows stamped 0; sort the log by time and drop repeated stamps"
                )
        if self.epoch and zero.any():
            rows = np.flatnonzero(zero)
            self.zero_rows += len(rows)
            self.zero_first = self.zero_first or where(int(rows[0]))
            rows_kept = np.flatnonzero(~zero)
            arrays = {key: arr[rows_kept] for key, arr in arrays.items()}
            values = {key: _take(val, rows_kept) for key, val in values.items()}
            kept = rows_kept if kept is None else kept[rows_kept]  # row numbers in the piece as read
            stamps = arrays["t"]
        if len(stamps) == 0:
            return None
        if self.unit is None:
            self._decide_unit(stamps)

        steps = np.diff(stamps, prepend=stamps[:1] if self.prev_stamp is None else [self.prev_stamp])
        check = steps[1:] if self.prev_stamp is None else steps
        if not (check > 0).all():
            i = int(np.argmin(check > 0)) + (1 if self.prev_stamp is None else 0)
            before = stamps[i - 1].item() if i > 0 else self.prev_stamp.item()
            raise LogFormatError(
                f"{name}: time is not strictly increasing at {where(i)}: {mapping['t']!r} = {stamps[i].item()!r} "
                f"follows {before!r} on the row before; sort the log by time and drop repeated stamps"
            )
        t = seconds(stamps, self.unit, self.offset)  # type: ignore[arg-type]
        t_steps = np.diff(t, prepend=t[:1] if self.prev_t is None else [self.prev_t])
        t_check = t_steps[1:] if self.prev_t is None else t_steps
        if not (t_check > 0).all():  # distinct stamps that float64 cannot tell apart
            i = int(np.argmin(t_check > 0)) + (1 if self.prev_t is None else 0)
            before = stamps[i - 1].item() if i > 0 else self.prev_stamp.item()
            raise LogFormatError(
                f"{name}: {where(i)}: stamps {before!r} and {stamps[i].item()!r} are equal "
                "in float64 seconds; give the time column in a coarser unit"
            )
        if self.first_step is None and len(t) > 1:
            self.first_step = float(np.median(np.diff(t)))
        if self.n == 0 and len(t):
            self.first_stamp, self.first_t = float(stamps[0]), float(t[0])
        self.prev_stamp, self.prev_t, self.last_t = stamps[-1], float(t[-1]), float(t[-1])
        self.n += len(t)

        eta = np.column_stack([arrays[required[1]], arrays[required[2]]]).astype(np.float64, copy=False)
        tau = np.column_stack([arrays["tau_r"], arrays["tau_l"]]).astype(np.float64, copy=False)
        pose = self._optional("pose", POSE, values, where, required=False)
        reference = self._optional("reference", REFERENCE, values, where, required=self.reference_required)
        return WheelLog(t=t, eta=eta, tau=tau, source=name, pose=pose, reference=reference)

    def _other_topics(
        self, arrays: dict[str, np.ndarray], values: dict[str, Any], where: Callable[[int], str]
    ) -> tuple[dict[str, np.ndarray], dict[str, Any], np.ndarray | None]:
        """A merged export's piece without the rows where every wheel speed and effort is empty (rows of other
        topics, which such an export interleaves); (arrays, values, the kept rows' indices or None)."""
        empty = np.ones(len(arrays["t"]), dtype=bool)
        for key in self.required[1:]:
            arr = arrays[key]
            empty &= np.isnan(arr) if arr.dtype.kind == "f" else np.zeros(len(arr), dtype=bool)
        if not empty.any():
            return arrays, values, None
        self.empty_rows += int(empty.sum())
        self.empty_first = self.empty_first or where(int(np.argmax(empty)))
        kept = np.flatnonzero(~empty)
        return {k: a[kept] for k, a in arrays.items()}, {k: _take(v, kept) for k, v in values.items()}, kept

    def _stamps(self, stamps: np.ndarray, where: Callable[[int], str]) -> np.ndarray:
        """The time column in the kind (integer or float) of the first piece's."""
        kind = "i" if stamps.dtype.kind in "iu" else "f"
        if self.kind is None:
            self.kind = kind
        elif kind != self.kind:
            if self.kind == "f":
                return stamps.astype(np.float64)
            whole = stamps == np.round(stamps)
            if not whole.all():
                i = int(np.argmin(whole))
                raise LogFormatError(
                    f"{self.name}: {where(i)}: time stamp {stamps[i].item()!r} has decimals where the rows before "
                    f"hold whole numbers; give the time column one kind of number (or {option('time_unit', 's')} with "
                    "decimals)"
                )
            return stamps.astype(np.int64)
        return stamps.astype(np.int64) if stamps.dtype.kind == "u" else stamps

    def _decide_unit(self, stamps: np.ndarray) -> None:
        tcol = self.mapping["t"]
        unit = self.time_unit
        if self.hint is not None:
            if self.time_unit not in ("auto", self.hint):
                self.notes.append(f"--time-unit {self.time_unit} ignored: the column's type says {self.hint}")
            unit = self.hint
        elif self.time_unit == "auto":
            if stamps.dtype.kind in "iu":
                unit = "ns"
                self.notes.append(
                    f"time column {tcol!r} holds integers: read as integer nanoseconds "
                    "(use --time-unit s, ms or us if it counts other units)"
                )
            else:
                unit = "s"
                largest = float(np.max(np.abs(stamps)))
                for candidate, low in (("ns", 1e16), ("us", 1e13)):
                    if largest >= low:  # as seconds: over 300,000 years; as ns or us since the epoch: today
                        unit = candidate
                        self.notes.append(
                            f"time column {tcol!r} holds floats up to {largest:.4g}: too large for seconds, read "
                            f"as {candidate} since the Unix epoch (use --time-unit to say otherwise)"
                        )
                        break
        self.unit = unit
        # Decided on the first piece, before the log's last stamp is known: relative already from
        # ABSOLUTE_LIMIT_S / 2 (48 days) on, so that a log may run 48 more days and keep 1 ns resolution.
        self.offset = None
        if stamps.dtype.kind in "iu" or unit != "s":
            per_s = PER_SECOND[unit]
            largest = max(abs(float(stamps[0])), abs(float(stamps[-1]))) / per_s
            if largest >= ABSOLUTE_LIMIT_S / 2:
                self.offset = int(stamps[0]) if stamps.dtype.kind in "iu" else float(stamps[0])

    def _optional(
        self, label: str, keys: tuple[str, ...], values: dict[str, Any], where: Callable[[int], str], required: bool
    ) -> np.ndarray | None:
        """The optional columns ``keys`` (the pose, the reference) as (n, len(keys)), or None: when one is absent, or,
        unless ``required`` (named by --columns), with a note when a cell is unusable; they are then dropped for the
        rest of the log (``self.dropped``)."""
        if label in self.dropped:
            return None
        if not all(k in values for k in keys):
            self.dropped.add(label)
            return None
        cols = []
        for key in keys:
            try:
                arr = _numeric(values[key], key, self.mapping[key], self.name, where).astype(np.float64, copy=False)
                i = _first_nonfinite(arr)
                problem = None if i is None else _nonfinite_message(arr, i, self.mapping[key], self.name, where)
                short = None if problem is None else problem.split(";")[0]  # the cell, without the fix
            except LogFormatError as err:
                problem = short = str(err)
            if problem is not None:
                if required:
                    raise LogFormatError(problem)
                self.notes.append(f"{label} columns ignored: {short.removeprefix(self.name + ': ')}")
                self.dropped.add(label)
                return None
            cols.append(arr)
        return np.column_stack(cols)

    def finish(self) -> list[str]:
        """The notes of the whole log; raises LogFormatError for a log with fewer than MIN_SAMPLES samples."""
        name, tcol, notes = self.name, self.mapping["t"], list(self.notes)
        if self.held_zeros > 1:  # only zeros: time stood still
            raise LogFormatError(
                f"{name}: time is not strictly increasing: all {self.held_zeros} rows are stamped 0; give the log "
                "its time stamps"
            )
        if self.n == 0 and self.zero_rows == 0 and self.held_zeros == 0:
            raise LogFormatError(
                f"{name}: has a header but no data rows; give a log with at least {MIN_SAMPLES} samples"
            )
        if self.n < MIN_SAMPLES:
            raise LogFormatError(
                f"{name}: only {self.n} samples; identification needs at least {MIN_SAMPLES}, so record a longer log"
            )
        if self.empty_rows:
            notes.insert(
                0,
                f"{self.empty_rows} rows without any wheel speed or effort (other topics' samples, which a "
                f"{MERGED_TIME!r} export interleaves) were dropped (first: {self.empty_first})",
            )
        if self.zero_rows:
            notes.insert(
                0,
                f"{self.zero_rows} rows with time stamp 0 among epoch times were dropped as bad stamps "
                f"(first: {self.zero_first})",
            )
        if self.offset is not None:
            notes.append(
                f"time stored relative to the first stamp {self.offset!r} {self.unit} (t = 0 there) so that float64 "
                "seconds keep 1 ns resolution"
            )
        if self.unit == "s" and self.kind == "f" and abs(self.last_t) >= 1e11:
            notes.append(
                f"time column {tcol!r} reaches {self.last_t:.3g} s (over 3000 years): if it counts ms, us or ns, "
                "say so with --time-unit"
            )
        elif self.unit == "ns" and self.time_unit == "auto" and self.hint is None and self.n > 1:
            mean_step = (self.last_t - self.first_t) / (self.n - 1)  # the whole log's, not its first piece's
            if mean_step < MIN_PLAUSIBLE_STEP_S:
                raise LogFormatError(implausible_step(name, tcol, mean_step, self.first_stamp))
        if any(self.mapping[k] != k for k in self.required):
            notes.append(
                "columns read as "
                + ", ".join(f"{k} = {self.mapping[k]!r}" for k in self.required if self.mapping[k] != k)
            )
        return notes


def _take(values: Any, rows: np.ndarray) -> Any:
    """Rows of a column as read (a numpy array or a pandas Series), renumbered from 0."""
    if isinstance(values, np.ndarray):
        return values[rows]
    return values.iloc[rows].reset_index(drop=True)
