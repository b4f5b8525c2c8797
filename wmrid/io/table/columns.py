"""Column names: the ``--columns`` mapping from canonical names to a file's, and which column serves each role."""

from __future__ import annotations

import difflib
import re

from wmrid.core.errors import LogFormatError, UsageError, option
from wmrid.core.wheel_log import CANONICAL, POSE, POSITION, REFERENCE

#: The speed columns, which the position columns (:data:`POSITION`) may replace.
SPEED = ("eta_r", "eta_l")


def suggest(name: str, candidates: list[str] | tuple[str, ...], cutoff: float = 0.6) -> str | None:
    """The closest candidate to ``name`` (case-insensitive difflib match), if any is close."""
    lowered = {c.lower(): c for c in candidates}
    hit = difflib.get_close_matches(name.lower(), list(lowered), n=1, cutoff=cutoff)
    return lowered[hit[0]] if hit else None


def parse_column_mapping(text: str) -> dict[str, str]:
    """Parse the ``--columns`` option: ``"t=time,eta_r=vel_right,tau_l=effort_left"``.

    Keys are canonical names (t, eta_r, eta_l, tau_r, tau_l, x, y, phi); values are column names in the
    log.  Returns {canonical: source name}.  Raises :class:`UsageError` on anything else.
    """
    from wmrid.io.ros.field_paths import split_outside_quotes  # ROS field paths (~8 ms): only a --columns mapping

    mapping: dict[str, str] = {}
    example = "t=time,eta_r=vel_right,tau_l=effort_left"
    for item in split_outside_quotes(text, ","):
        item = item.strip()
        if not item:
            continue
        key, sep, value = item.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key or not value:
            raise UsageError(
                f"{option('columns')}: {item!r} is not NAME=COLUMN; write e.g. {option('columns')} {example}"
            )
        check_key(key, "--columns")
        if len(value) >= 2 and value[0] == value[-1] == '"':  # a column name with a comma, in quotes
            value = value[1:-1]
        if key in mapping:
            raise UsageError(f"{option('columns')}: {key!r} is given twice ({mapping[key]!r} and {value!r})")
        mapping[key] = value
    if not mapping:
        raise UsageError(f"{option('columns')} is empty; write e.g. {option('columns')} {example}")
    seen: dict[str, str] = {}
    for key, value in mapping.items():
        if value in seen:
            raise UsageError(
                f"{option('columns')} maps both {seen[value]} and {key} to the column {value!r}; each needs its own "
                "column"
            )
        seen[value] = key
    return mapping


def check_key(key: str, what: str) -> None:
    if key not in CANONICAL:
        close = suggest(key, CANONICAL)
        hint = f" (did you mean {close!r}?)" if close else ""
        raise UsageError(f"{what}: {key!r} is not a column wmrid knows{hint}; use one of {', '.join(CANONICAL)}")


#: Words that say what a column holds (its name split into words, lower case: see :func:`words`).
_SIDE_WORDS = {"r": ("right", "r", "rt", "rgt"), "l": ("left", "l", "lt", "lft")}
_SPEED_WORDS = ("velocity", "vel", "speed", "omega")
_EFFORT_WORDS = ("effort", "torque", "tau")
_POSITION_WORDS = ("position", "pos", "angle")
#: A column with one of these words is a command, a set-point or a position, not a measured speed or effort.
_NOT_MEASURED = (
    "cmd", "command", "commanded", "desired", "des", "ref", "reference", "target", "setpoint", "sp", "goal", "position",
    "pos", "limit", "max", "min", "error", "err", "diff", "delta",
)  # fmt: skip
#: Time columns by name: PlotJuggler's ``__time`` first, then the usual words.
_TIME_NAMES = ("__time", "time", "timestamp", "stamp", "t_s", "time_s")


def words(column: str) -> list[str]:
    """A column name as lower-case words: split at anything not a letter or digit, at lower-to-upper case changes
    and between letters and digits (``/joint_states/right_wheel_joint/velocity`` -> joint, states, right,
    wheel, joint, velocity; ``velLeft`` -> vel, left)."""
    spaced = re.sub(r"(?<=[a-z])(?=[A-Z])|(?<=[A-Za-z])(?=[0-9])|(?<=[0-9])(?=[A-Za-z])", " ", column)
    return [w for w in re.split(r"[^A-Za-z0-9]+", spaced.lower()) if w]


def guess_candidates(key: str, columns: list[str]) -> list[str]:
    """The columns whose names say they hold ``key`` (t, eta_r, eta_l, tau_r, tau_l, pos_r, pos_l), in file order.

    A wheel signal: a speed word (velocity, vel, speed, omega), an effort word (effort, torque, tau) or a position
    word (position, pos, angle), one side (right/r/rt or left/l/lt, not both), no word of the other quantities and no
    word of a command or set-point (cmd, desired, ref, target, ...; for speeds and efforts also position, pos).
    Time: a column named ``__time`` (PlotJuggler), else ``time``, ``timestamp``, ``stamp`` (case-insensitive), the
    first of those names present.
    """
    if key == "t":
        lowered = {c.lower(): c for c in columns}
        return next(([lowered[n]] for n in _TIME_NAMES if n in lowered), [])
    kinds = {"eta": _SPEED_WORDS, "tau": _EFFORT_WORDS, "pos": _POSITION_WORDS}
    quantity = set(kinds[key[:3]])
    other = {w for kind, ws in kinds.items() if kind != key[:3] for w in ws}
    not_measured = set(_NOT_MEASURED) - quantity
    side, opposite = set(_SIDE_WORDS[key[-1]]), set(_SIDE_WORDS["l" if key[-1] == "r" else "r"])
    out = []
    for column in columns:
        w = set(words(column))
        if w & quantity and w & side and not w & opposite and not w & other and not w & not_measured:
            out.append(column)
    return out


def wheel_columns(present: list[str], mapping: dict[str, str], explicit: set[str], velocity_from: str) -> tuple:
    """The wheel columns a table log is read by: :data:`SPEED` or :data:`POSITION`, or () when ``velocity_from`` is
    "auto" and the log has neither (both present by name, or each found by :func:`guess_candidates`).

    "velocity": the speeds; "position": the positions; "auto": the speeds when named by ``--columns`` or there (each
    present by its name or said by some column's name: several candidates are then refused by :func:`select`), else
    the positions when named or there.
    """
    if velocity_from == "position":
        return POSITION
    if velocity_from == "velocity" or explicit & set(SPEED):
        return SPEED
    if explicit & set(POSITION):
        return POSITION

    def found(keys: tuple[str, ...]) -> bool:
        return all(mapping[k] in present or guess_candidates(k, present) for k in keys)

    return SPEED if found(SPEED) else POSITION if found(POSITION) else ()


def select(
    present: list[str],
    mapping: dict[str, str],
    explicit: set[str],
    name: str,
    notes: list[str] | None = None,
    velocity_from: str = "velocity",
) -> dict[str, str]:
    """{canonical: column in the file} for the required columns and, when all three exist, the pose.

    The wheel columns are the speeds eta_r, eta_l or, by ``velocity_from`` (:func:`wheel_columns`), the positions
    pos_r, pos_l: the keys of the result say which.  When required columns are neither present by their canonical
    names nor named by ``--columns``, and for each exactly one column says it is that signal
    (:func:`guess_candidates`), those are used, ``mapping`` is updated with them and ``notes`` says so.  Raises one
    :class:`LogFormatError` naming every missing column, the columns there are, close matches (or the several columns
    a guess could not choose between), and the ``--columns`` option that would fix it.
    """
    wheel = wheel_columns(present, mapping, explicit, velocity_from)
    try:
        return _select(present, mapping, explicit, name, notes, ("t", *(wheel or SPEED), "tau_r", "tau_l"))
    except LogFormatError as err:
        if not wheel:  # neither speeds nor positions: say both ways out
            raise LogFormatError(f"{err} (or, for wheel positions, pos_r=...,pos_l=...)") from None
        if wheel == SPEED and velocity_from == "velocity" and wheel_columns(present, mapping, explicit, "auto"):
            raise LogFormatError(
                f"{err}; or derive the speeds from the log's wheel positions with {option('velocity_from', 'auto')}"
            ) from None
        raise


def _select(
    present: list[str],
    mapping: dict[str, str],
    explicit: set[str],
    name: str,
    notes: list[str] | None,
    required: tuple[str, ...],
) -> dict[str, str]:
    """:func:`select` for the required columns ``required``."""
    needed = list(required) + [k for k in POSE if k in explicit]
    if explicit & set(REFERENCE):  # one reference column named: both are needed
        needed += list(REFERENCE)
    missing = [k for k in needed if mapping[k] not in present]
    guessable = [k for k in missing if k in required and k not in explicit]
    if guessable:
        taken = {mapping[k] for k in needed if k not in missing}
        found = {key: guess_candidates(key, [c for c in present if c not in taken]) for key in guessable}
        ambiguous = {key: cands for key, cands in found.items() if len(cands) > 1}
        unique = {key: cands[0] for key, cands in found.items() if len(cands) == 1}
        if ambiguous:
            parts = [f"{key} could be any of {', '.join(repr(c) for c in cands)}" for key, cands in ambiguous.items()]
            fixes = ",".join(f"{key}={cands[0]}" for key, cands in ambiguous.items())
            raise LogFormatError(
                f"{name}: cannot tell which column to use: {'; '.join(parts)}; choose with {option('columns')} {fixes}"
            )
        if len(unique) == len(missing) and len(set(unique.values())) == len(unique):
            mapping.update(unique)  # the caller's mapping: its messages name the columns used
            missing = []
            if notes is not None:
                notes.append(
                    f"columns for {', '.join(unique)} guessed from their names (the note 'columns read as' lists "
                    f"them); give {option('columns')} to choose others"
                )
    if missing:
        parts, fixes = [], []
        taken = {mapping[k] for k in needed if k not in missing}
        free = [c for c in present if c not in taken]
        for key in missing:
            col = mapping[key]
            close = suggest(col, free, cutoff=0.7)
            if close:
                free.remove(close)
            origin = f" (given for {key} by --columns)" if key in explicit else ""
            parts.append(f"{col!r}{origin}" + (f" (did you mean {close!r}?)" if close else ""))
            fixes.append(f"{key}={close or '...'}")
        shown = ", ".join(repr(c) for c in present[:20])
        if len(present) > 20:
            shown += f", ... ({len(present)} in all)"
        label = "column" if len(missing) == 1 else "columns"
        raise LogFormatError(
            f"{name}: no {label} {', '.join(parts)}; the columns are {shown or 'none'}; "
            f"name the log's columns with {option('columns')} {','.join(fixes)}"
        )
    chosen = {key: mapping[key] for key in required}
    for optional in (POSE, REFERENCE):
        if all(mapping[k] in present for k in optional):
            chosen.update({key: mapping[key] for key in optional})
    return chosen
