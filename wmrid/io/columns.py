"""Column names: the ``--columns`` mapping from canonical names to a file's, and which column serves each role."""

from __future__ import annotations

import difflib
from typing import TYPE_CHECKING

from wmrid.core.errors import LogFormatError, UsageError, option

if TYPE_CHECKING:
    pass
from wmrid.core.wheel_log import CANONICAL, POSE, REFERENCE, REQUIRED


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
    mapping: dict[str, str] = {}
    example = "t=time,eta_r=vel_right,tau_l=effort_left"
    for item in text.split(","):
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


def select(present: list[str], mapping: dict[str, str], explicit: set[str], name: str) -> dict[str, str]:
    """{canonical: column in the file} for the required columns and, when all three exist, the pose.

    Raises one :class:`LogFormatError` naming every missing column, the columns there are, close
    matches, and the ``--columns`` option that would fix it.
    """
    needed = list(REQUIRED) + [k for k in POSE if k in explicit]
    if explicit & set(REFERENCE):  # one reference column named: both are needed
        needed += list(REFERENCE)
    missing = [k for k in needed if mapping[k] not in present]
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
    chosen = {key: mapping[key] for key in REQUIRED}
    for optional in (POSE, REFERENCE):
        if all(mapping[k] in present for k in optional):
            chosen.update({key: mapping[key] for key in optional})
    return chosen
