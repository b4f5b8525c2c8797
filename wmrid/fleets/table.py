"""A fleet's logs and results on disk: the manifest that lists the logs (:func:`read_manifest`), the logs found from
paths, globs and folders (:func:`find_logs`), the robot id and time a path states (:func:`id_and_time_from_path`),
and the results table, one row per log (:data:`SCHEMA`, :func:`write_table`, :func:`read_table`).

The table is Parquet with a fixed schema (``wmrid_fleet_schema`` = :data:`SCHEMA_VERSION` in its metadata): the
same columns, types and order whatever the logs held, so that tables of different runs concatenate.
"""

from __future__ import annotations

import datetime as dt
import functools
import glob
import hashlib
import json
import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from wmrid.core.errors import LogFormatError, UsageError, option
from wmrid.estimators.options import delay_value

SCHEMA_VERSION = "3"
#: Schema versions read (an older table lacks the columns added since, :data:`ADDED_IN_2` and :data:`ADDED_IN_3`:
#: read as nulls, so that it can be resumed).
READABLE_VERSIONS = ("1", "2", "3")
#: Columns added by schema 2: each wheel's mean absolute speed over the log (rad/s, at the wheel) and the
#: correlation of that wheel's viscous and Coulomb friction estimates (what the fleet review needs for the
#: friction torque at a robot's typical speed, :mod:`wmrid.fleets.review`).
ADDED_IN_2 = ("speed_r", "speed_l", "Fv1_Fd1_corr", "Fv2_Fd2_corr")
#: Columns added by schema 3: the payload estimated against the robot file (``--payload``; null without it), mass kg,
#: position x, y m and inertia kg m^2 about its centre, each with its std.
ADDED_IN_3 = tuple(f"payload_{name}{suffix}" for name in ("mass", "x", "y", "inertia") for suffix in ("", "_std"))

#: The base parameters of every row (value and ``NAME_std``), SI units as ``identify`` reports them: the entries of
#: m = M^-1 and of M, the Coriolis coefficient, the wheels' viscous and Coulomb friction, the casters' drag (null
#: unless identified with it).
PARAMETERS = ("m11", "m12", "m22", "M11", "M12", "M22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2", "Cv", "Cw")

#: Suffixes of the files :func:`find_logs` takes from a folder (a folder holding metadata.yaml is one recording).
LOG_SUFFIXES = (
    ".mcap", ".bag", ".bag.active", ".db3", ".parquet", ".csv", ".csv.gz", ".csv.bz2", ".csv.xz", ".csv.zst",
)  # fmt: skip

#: A date, optionally with a time, in a file or folder name: 2026-03-14, 2026-03-14T08-30-00, 20260314_083000.
DATE_IN_NAME = re.compile(
    r"(?P<y>\d{4})-?(?P<mo>\d{2})-?(?P<d>\d{2})(?:[T_ -]?(?P<h>\d{2})[:-]?(?P<mi>\d{2})[:-]?(?P<s>\d{2}))?"
)

#: Manifest columns besides the per-log options.
MANIFEST_COLUMNS = ("log", "robot_id", "robot", "time")


@functools.lru_cache(maxsize=1)
def _schema():
    """The schema, made once (a pyarrow schema is immutable; making it took 0.1 ms, paid per row of 10^5)."""
    import pyarrow as pa  # pyarrow (~30 ms, extra [fleet]): only the table's schema

    fields = [
        ("robot_id", pa.string()), ("log", pa.string()), ("robot", pa.string()), ("sha256", pa.string()),
        ("bytes", pa.int64()), ("start_time", pa.timestamp("us", tz="UTC")), ("time_source", pa.string()),
        ("duration_s", pa.float64()), ("samples", pa.int64()), ("rate_hz", pa.float64()), ("method", pa.string()),
        ("form", pa.string()), ("effort_unit", pa.string()), ("options", pa.string()), ("options_key", pa.string()),
    ]  # fmt: skip
    for name in PARAMETERS:
        fields += [(name, pa.float64()), (f"{name}_std", pa.float64())]
    fields += [(name, pa.float64()) for name in (*ADDED_IN_2, *ADDED_IN_3)]
    fields += [
        ("flags", pa.list_(pa.field("element", pa.string()))),
        ("warnings", pa.list_(pa.field("element", pa.string()))), ("fit_r", pa.float64()),
        ("fit_l", pa.float64()), ("run_time_s", pa.float64()), ("worker", pa.string()),
        ("wmrid_version", pa.string()), ("error", pa.string()),
    ]  # fmt: skip
    return pa.schema(fields, metadata={b"wmrid_fleet_schema": SCHEMA_VERSION.encode()})


def schema():
    """The table's pyarrow schema (columns in order; see docs/reference/fleet-table.md)."""
    return _schema()


@functools.lru_cache(maxsize=1)
def column_names() -> tuple[str, ...]:
    return tuple(_schema().names)


def empty_row(**given: Any) -> dict[str, Any]:
    """A row of the table with every column None (lists empty) but those ``given``."""
    row: dict[str, Any] = dict.fromkeys(column_names())
    row["flags"], row["warnings"] = [], []
    unknown = set(given) - set(row)
    if unknown:
        raise ValueError(f"not columns of the fleet table: {sorted(unknown)}")
    row.update(given)
    return row


def to_arrow(rows: Sequence[dict[str, Any]]):
    """The rows as a pyarrow Table of :func:`schema` (a missing column is null)."""
    import pyarrow as pa  # pyarrow (~30 ms, extra [fleet]): only a table made

    sch = _schema()
    columns = {name: [row.get(name) for row in rows] for name in sch.names}
    for name in ("flags", "warnings"):
        columns[name] = [list(v) if v is not None else [] for v in columns[name]]
    return pa.Table.from_pydict(columns, schema=sch)


def write_table(rows: Any, path: str | os.PathLike[str], *, force: bool = False) -> None:
    """Write the rows (dicts, or a pyarrow Table of :func:`schema`) as the fleet table at ``path`` (Parquet),
    atomically: a reader sees the old table or the new one, never half of one."""
    import pyarrow as pa  # pyarrow (~40 ms, extra [fleet]): only a table written
    import pyarrow.parquet as pq  # pyarrow: only a table written

    # runtime.atomic (tempfile): only a table written (wmrid.fleets.run stays lazy)
    from wmrid.runtime.atomic import atomic_output

    table = rows if isinstance(rows, pa.Table) else to_arrow(rows)
    with atomic_output(path, force=force) as fh:
        pq.write_table(table, fh, compression="zstd")


def read_table(path: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """The rows of a fleet table written by :func:`write_table` (start times as aware UTC datetimes)."""
    return read_arrow(path).to_pylist()


def read_arrow(path: str | os.PathLike[str], *, as_input: bool = True):
    """The fleet table at ``path`` as a pyarrow Table of :func:`schema` (its columns in order), checked.
    ``as_input`` False: not noted as an input of the command (``fleet --resume`` reads the table it then rewrites)."""
    import pyarrow as pa  # pyarrow (~40 ms, extra [fleet]): only a table read
    import pyarrow.parquet as pq  # pyarrow: only a table read

    # runtime.atomic (tempfile): only a table read (wmrid.fleets.run stays lazy)
    from wmrid.runtime.atomic import register_input

    name = os.fspath(path)
    if as_input:
        register_input(name)
    try:
        if not os.path.isdir(name):
            with open(name, "rb"):  # a file that cannot be read is said as such, not in Arrow's words
                pass
        table = pq.read_table(name)
    except FileNotFoundError:
        raise UsageError(f"{name}: no such fleet table; run `wmrid fleet LOGS -o {name}` first") from None
    except PermissionError as err:
        raise LogFormatError(f"{name}: cannot be read ({err.strerror}); check its permissions") from None
    except (OSError, pa.ArrowException) as err:
        raise LogFormatError(f"{name}: not a Parquet fleet table ({_one_line(err)})") from None
    meta = table.schema.metadata or {}
    version = meta.get(b"wmrid_fleet_schema", b"").decode()
    if version not in READABLE_VERSIONS:
        found = f"schema {version}" if version else "no wmrid_fleet_schema in its metadata"
        raise LogFormatError(
            f"{name}: not a wmrid fleet table of schema {', '.join(READABLE_VERSIONS[:-1])} or {READABLE_VERSIONS[-1]} "
            f"({found}); make it with "
            "`wmrid fleet`"
        )
    if version != SCHEMA_VERSION:
        for column in (*ADDED_IN_2, *ADDED_IN_3):
            if column not in table.column_names:
                table = table.append_column(column, pa.nulls(len(table), pa.float64()))
    missing = [n for n in column_names() if n not in table.column_names]
    if missing:
        raise LogFormatError(f"{name}: the fleet table lacks the columns {', '.join(missing)}; remake it")
    table = table.select(list(column_names()))
    schema = _schema()
    for wanted in schema:  # column by column, so that a column of the wrong type is named (a forged or edited table)
        column = table.column(wanted.name)
        if column.type == wanted.type:
            continue
        try:
            column.cast(wanted.type)
        except (pa.ArrowException, ValueError, TypeError) as err:
            raise LogFormatError(
                f"{name}: column {wanted.name} holds {column.type} values that cannot be read as {wanted.type}; remake "
                "the table with `wmrid fleet`"
            ) from err
    return table.cast(schema)


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split())[:300]


# ----------------------------------------------------------------------------------------------------------------
# Which logs, and whose


@dataclass(frozen=True)
class LogEntry:
    """One log of the fleet: its path(s), robot id, robot file, time stamp (aware UTC datetime or None), where the
    time came from ("manifest", "path", None: the log's own first stamp when it is an epoch time), and the per-log
    options of a manifest row (identify's keywords and :class:`~wmrid.api.inputs.LogOptions` fields)."""

    log: str
    robot_id: str
    robot: str | None = None
    time: dt.datetime | None = None
    time_source: str | None = None
    options: dict[str, Any] = field(default_factory=dict)


def _is_log_file(path: Path) -> bool:
    name = path.name.lower()
    return path.is_file() and any(name.endswith(s) for s in LOG_SUFFIXES) and not name.endswith(".truth.json")


def find_logs(paths: Sequence[str]) -> list[str]:
    """The logs named by ``paths``: files as given, globs (``**`` recursive) expanded, folders searched for log
    files (:data:`LOG_SUFFIXES`); a folder with a metadata.yaml (a rosbag2 recording) is one log.  Sorted within
    each argument, duplicates dropped; an argument that names nothing is an error."""
    out: list[str] = []
    seen: set[str] = set()

    def add(item: str) -> None:
        key = os.path.realpath(item)
        if key not in seen:
            seen.add(key)
            out.append(item)

    for arg in paths:
        if os.path.isdir(arg):
            found = _logs_in_folder(Path(arg))
            if not found:
                raise UsageError(f"{arg}: a folder with no log in it ({', '.join(LOG_SUFFIXES)} or rosbag2 folders)")
            for f in found:
                add(f)
        elif os.path.exists(arg):
            add(arg)
        elif glob.has_magic(arg):
            matches = sorted(safe_glob(arg))
            logs = [m for m in matches if os.path.isfile(m) or (Path(m) / "metadata.yaml").is_file()]
            if not logs:
                raise UsageError(f"{arg}: the pattern matches no log")
            for m in logs:
                add(m)
        else:
            raise UsageError(f"{arg}: no such file or folder")
    return out


#: The most folders one pattern's ``**`` may walk (a real fleet's tree holds a few thousand).
GLOB_FOLDERS = 200_000


def safe_glob(pattern: str, limit: int = GLOB_FOLDERS) -> list[str]:
    """The paths ``pattern`` matches, as ``glob.glob(pattern, recursive=True)`` gives them (``**`` any number of
    folders, names starting with "." left out) but following no symbolic-link loop: each ``**`` walks every real
    folder once (by device and inode; a link back up the tree, e.g. ``L/a -> .``, is not entered again, where glob
    follows it until the path is too long: two such links and it never ends), at most ``limit`` folders in all
    (UsageError past it)."""
    left = [limit]
    return _glob(pattern, left, pattern)


def _glob(pattern: str, left: list[int], given: str) -> list[str]:
    parts = pattern.split("/")
    if "**" not in parts:  # no recursion: glob walks one folder level per part, and cannot loop
        return glob.glob(pattern)
    i = parts.index("**")
    head = "/".join(parts[:i]) or ("/" if pattern.startswith("/") else "")
    rest = "/".join(parts[i + 1 :])
    bases = glob.glob(head) if glob.has_magic(head) else [head]
    out: list[str] = []
    for base in bases:
        for folder in _folders(base, left, given):
            if not rest and len(parts) > i + 1:  # "**/": the folders alone, as "folder/"
                if folder:
                    out.append(os.path.join(folder, ""))
            elif not rest:  # a trailing **: the folders themselves (the base as "base/"), and their files
                if folder != base or base:
                    out.append(folder if folder != base else os.path.join(base, ""))
                listing = folder or "."
                out += [os.path.join(folder, n) for n in sorted(os.listdir(listing)) if not n.startswith(".")
                        and not os.path.isdir(os.path.join(listing, n))]  # fmt: skip
            else:
                out += _glob(os.path.join(glob.escape(folder), rest) if folder else rest, left, given)
    return out


def _folders(base: str, left: list[int], given: str) -> list[str]:
    """``base`` ("" the current folder) and the folders under it (links followed), each real folder once, in name
    order; ``left[0]`` counts down the folders the pattern may still walk."""
    out: list[str] = []
    seen: set[tuple[int, int]] = set()
    stack = [base]
    while stack:
        folder = stack.pop()
        try:
            st = os.stat(folder or ".")
        except OSError:
            continue
        if (st.st_dev, st.st_ino) in seen:  # a link back to a folder already walked: a loop, or a second name
            continue
        seen.add((st.st_dev, st.st_ino))
        left[0] -= 1
        if left[0] < 0:
            raise UsageError(
                f"{given}: the pattern walks more than {GLOB_FOLDERS:,} folders; narrow it (a folder instead of **, "
                "or a longer fixed start)"
            )
        out.append(folder)
        try:
            with os.scandir(folder or ".") as entries:
                children = sorted(e.name for e in entries if not e.name.startswith(".") and _is_folder(e))
        except OSError:
            continue
        stack.extend(os.path.join(folder, c) for c in reversed(children))
    return out


def _is_folder(entry: os.DirEntry) -> bool:
    try:
        return entry.is_dir()  # follows a link: its target is walked once, whatever name reaches it first
    except OSError:
        return False


def _logs_in_folder(folder: Path) -> list[str]:
    if (folder / "metadata.yaml").is_file():
        return [str(folder)]
    found: list[str] = []
    for root, dirs, files in os.walk(folder):
        dirs.sort()
        here = Path(root)
        recordings = [d for d in dirs if (here / d / "metadata.yaml").is_file()]
        found += [str(here / d) for d in recordings]
        dirs[:] = [d for d in dirs if d not in recordings and not d.startswith(".")]
        found += [str(here / f) for f in sorted(files) if _is_log_file(here / f)]
    return sorted(found)


def id_and_time_from_path(path: str, pattern: str | None = None) -> tuple[str, dt.datetime | None]:
    """(robot id, time or None) that a log's path states.

    ``pattern``: a regular expression searched in the path (with "/" separators) with a named group ``robot`` and
    optionally ``time`` (ISO 8601 or a :data:`DATE_IN_NAME` form).  Without it, the robot id is the name of the
    folder the log is in (of a rosbag2 folder: the folder above it) and the time the last date in the log's own
    name (e.g. ``2026-03-14T08-30-00``), UTC.
    """
    if pattern is not None:
        match = re.search(pattern, Path(path).as_posix())
        if match is None:
            raise UsageError(f"{path}: {option('id_pattern', pattern)} does not match this path")
        robot = match.groupdict().get("robot")
        if not robot:
            raise UsageError(f"{option('id_pattern', pattern)} has no (?P<robot>...) group, or it matched nothing")
        text = match.groupdict().get("time")
        return robot, (parse_time(text, f"{path}: the time {text!r} of {option('id_pattern')}") if text else None)
    p = Path(path)
    robot = p.parent.name or os.path.basename(os.path.abspath(p.parent)) or "robot"
    if p.is_dir() and (p / "metadata.yaml").is_file() and not DATE_IN_NAME.search(p.name):
        robot = p.parent.name or robot
    stamps = [s for s in (_from_match(m) for m in DATE_IN_NAME.finditer(p.name)) if s is not None]
    return robot, (stamps[-1] if stamps else None)  # the last valid date: digits that are no date are skipped


def _from_match(m: re.Match) -> dt.datetime | None:
    parts = [int(m.group(g)) if m.group(g) else 0 for g in ("y", "mo", "d", "h", "mi", "s")]
    try:
        return dt.datetime(*parts, tzinfo=dt.timezone.utc)
    except ValueError:  # 20261399: digits, not a date
        return None


def parse_time(value: Any, where: str) -> dt.datetime:
    """A time stamp as an aware UTC datetime: ISO 8601 text (no zone: UTC), a date in a :data:`DATE_IN_NAME` form,
    seconds since the Unix epoch, a datetime or a pandas Timestamp."""
    if isinstance(value, dt.datetime):
        return value if value.tzinfo else value.replace(tzinfo=dt.timezone.utc)
    if hasattr(value, "to_pydatetime"):
        return parse_time(value.to_pydatetime(), where)
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        if math.isfinite(value):
            try:
                return dt.datetime.fromtimestamp(float(value), tz=dt.timezone.utc)
            except (OverflowError, ValueError, OSError):
                raise UsageError(
                    f"{where}: {value!r} is not seconds since 1970 (milliseconds? give seconds or ISO 8601)"
                ) from None
    elif isinstance(value, str):
        text = value.strip()
        try:
            return parse_time(dt.datetime.fromisoformat(text.replace("Z", "+00:00")), where)
        except ValueError:
            m = DATE_IN_NAME.fullmatch(text)
            stamp = _from_match(m) if m else None
            if stamp is not None:
                return stamp
            try:
                seconds = float(text)
            except ValueError:
                seconds = None
            if seconds is not None:
                return parse_time(seconds, where)
    raise UsageError(f"{where}: not a time (ISO 8601 such as 2026-03-14T08:30:00Z, or seconds since 1970)")


def entries_from_paths(paths: Sequence[str], id_pattern: str | None = None) -> list[LogEntry]:
    """:class:`LogEntry` of each log :func:`find_logs` finds, robot id and time from the path."""
    out = []
    for log in find_logs(paths):
        robot_id, stamp = id_and_time_from_path(log, id_pattern)
        out.append(LogEntry(log, robot_id, None, stamp, "path" if stamp is not None else None))
    return out


def content_digest(path: str) -> tuple[str, int]:
    """(SHA-256 hex, bytes) of a log's content: of the file, or of a folder's files (names relative to it, sizes and
    hashes, in name order), read in blocks up to each file's size; a device or a FIFO is refused unread
    (:class:`wmrid.runtime.side_files.NotRegularFile`, an OSError)."""
    from wmrid.io.digest import file_digests  # io.digest: only on a worker (wmrid.fleets.run stays lazy)

    items = file_digests(path, regular_only=True)  # a device or a FIFO is refused unread (an OSError)
    if len(items) == 1 and not os.path.isdir(path):
        return items[0]["sha256"], int(items[0]["bytes"])
    h = hashlib.sha256()
    for item in items:
        rel = os.path.relpath(item["path"], path)
        h.update(f"{rel}\0{item['bytes']}\0{item['sha256']}\n".encode())
    return h.hexdigest(), sum(int(i["bytes"]) for i in items)


def options_key(options: dict[str, Any]) -> str:
    """A short hash of a log's effective options (canonical JSON): ``--resume`` re-runs a log whose options
    changed."""
    return hashlib.sha256(canonical_options(options).encode()).hexdigest()[:16]


def canonical_options(options: dict[str, Any]) -> str:
    """Options as JSON with sorted keys and no spaces: the table's "options" cell and what :func:`options_key`
    hashes.  ``delay`` as text (:func:`_delay_text`), whether it came as a number or as text."""
    if "delay" in options:
        options = {**options, "delay": _delay_text(options["delay"])}
    return json.dumps(options, sort_keys=True, separators=(",", ":"), default=str)


def _delay_text(value: Any) -> Any:
    """``delay`` as the table records it: "auto", or its seconds as the shortest text of the number ("0.02", "0"),
    as the command line passed the flag's text before it parsed it: a table it wrote resumes without running its logs
    again when the flag was written that way (another spelling, "1e-3" or "0.020", runs them once more), and a number
    from the command line and its text in a manifest give one key.  Parsed as the observer parses it
    (:func:`wmrid.estimators.options.delay_value`); a value it refuses is kept as it is (its row fails on its own)."""
    try:
        parsed = delay_value(value)
    except UsageError:
        return value
    if not isinstance(parsed, float):
        return parsed
    return str(int(parsed)) if parsed.is_integer() else repr(parsed)  # "0", as --delay 0 was written


def sort_table(table):
    """A table's rows by robot id, then time (rows without one last), then log."""
    return table.sort_by([("robot_id", "ascending"), ("start_time", "ascending"), ("log", "ascending")])
