"""A fleet's manifest read (:func:`read_manifest`): a table of logs (CSV or Parquet) with their robot, time and options
per row, each
path confined under the manifest's root, each value checked with its row named."""

from __future__ import annotations

import functools
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any, get_args, get_type_hints

from wmrid.core.errors import LogFormatError, UsageError, option
from wmrid.estimators.options import FIT_NAMES, MethodOptions, ObserverOptions
from wmrid.fleets.table import MANIFEST_COLUMNS, LogEntry, _one_line, id_and_time_from_path, parse_time
from wmrid.runtime.side_files import LOOP, broken_link, not_regular

_BOOL = {"true": True, "1": True, "yes": True, "false": False, "0": False, "no": False}


@functools.lru_cache(maxsize=1)
def _kinds() -> tuple[frozenset[str], frozenset[str]]:
    """(the options that are true/false, those that are numbers), by their names as manifest columns: read from the
    option objects' field types (LogOptions, ObserverOptions, MethodOptions under the command line's names), plus the
    rotor inertia."""
    # api.inputs: only a manifest read (wmrid.fleets.run, which imports this, stays lazy)
    from wmrid.api.inputs import LogOptions

    types = {**get_type_hints(LogOptions), **get_type_hints(ObserverOptions)}
    fit = get_type_hints(MethodOptions)
    types.update({name: fit[field] for name, field in FIT_NAMES.items()})
    flags = frozenset(n for n, t in types.items() if t is bool)
    numeric = frozenset(n for n, t in types.items() if t is float or set(get_args(t)) == {float, type(None)})
    return flags, numeric | {"rotor_inertia"}


def _option_value(name: str, value: Any, where: str) -> Any:
    """A manifest cell as the option's Python value (text kept for text options, numbers for numeric ones)."""
    flags, numeric = _kinds()
    if name in flags:
        if isinstance(value, bool):
            return value
        text = str(value).strip().lower()
        if text not in _BOOL:
            raise UsageError(f"{where}: {name} must be true or false, got {value!r}")
        return _BOOL[text]
    if name in numeric:
        try:
            return float(value)
        except (TypeError, ValueError):
            raise UsageError(f"{where}: {name} must be a number, got {value!r}") from None
    return value if name == "delay" and isinstance(value, (int, float)) else str(value).strip()


def _blank(value: Any) -> bool:
    """An empty manifest cell: None, NaN, NaT (a Parquet manifest's null time) or blank text."""
    if value is None:
        return True
    if isinstance(value, str):
        return not value.strip()
    try:
        import pandas as pd  # pandas (~0.2 s): only a manifest read

        return bool(pd.isna(value))
    except (TypeError, ValueError):
        return False


def read_manifest(
    path: str | os.PathLike[str],
    id_pattern: str | None = None,
    option_names: Sequence[str] = (),
    root: str | os.PathLike[str] | None = None,
) -> list[LogEntry]:
    """The logs a manifest lists (CSV or Parquet, one row per log).

    Columns: ``log`` (required; a path relative to the manifest's folder, or absolute), ``robot_id`` (else from the
    path, :func:`id_and_time_from_path`), ``robot`` (a robot file or built-in name), ``time`` (ISO 8601 or epoch
    seconds; else from the path or the log), and any of ``option_names`` (per-log options, e.g. ``speed_unit``,
    ``columns``, ``method``: :func:`wmrid.fleets.run.option_columns`); an empty cell is "not given".  Another column
    is refused by name.

    Each log is resolved (symbolic links and ``..`` followed: the entry's ``log`` is the real path) and must lie in
    ``root`` (default: the manifest's own folder; ``--manifest-root``), so that a manifest reaches only what the
    user meant to give it: a row resolving outside (``../../etc/passwd``, ``/etc/shadow``, a link out) is refused
    with its row, and so is one naming a device, a FIFO or a socket (only log files and rosbag2 folders are logs).
    A log that does not exist is left to its row's error, as before.
    """
    import pandas as pd  # pandas (~0.2 s): only a manifest read

    # runtime.atomic (tempfile): only a manifest read (wmrid.fleets.run stays lazy)
    from wmrid.runtime.atomic import register_input

    name = os.fspath(path)
    register_input(name)
    try:
        if name.lower().endswith(".parquet"):
            frame = pd.read_parquet(name)
        else:
            frame = pd.read_csv(name, dtype=str, keep_default_na=False, skipinitialspace=True)
    except FileNotFoundError:
        raise UsageError(f"{option('manifest', name)}: no such file") from None
    except (OSError, ValueError, ImportError) as err:
        raise LogFormatError(f"{name}: not a CSV or Parquet manifest ({_one_line(err)})") from None
    frame.columns = [str(c).strip() for c in frame.columns]
    if "log" not in frame.columns:
        raise UsageError(f"{name}: a manifest needs a 'log' column (one log per row); it has {list(frame.columns)}")
    allowed = set(MANIFEST_COLUMNS) | set(tuple(option_names))
    unknown = [c for c in frame.columns if c not in allowed]
    if unknown:
        raise UsageError(
            f"{name}: unknown manifest column(s) {', '.join(unknown)}; the columns are {', '.join(MANIFEST_COLUMNS)} "
            f"and the options {', '.join(tuple(option_names))}"
        )
    base = Path(name).parent
    fence = os.path.realpath(base if root is None else root)
    if root is not None and not os.path.isdir(fence):
        raise UsageError(
            f"{option('manifest_root', os.fspath(root))}: not a folder; give the folder that holds the logs"
        )
    entries = []
    folders: dict[str, str] = {}  # the real path of each folder the rows name (10^5 rows share a few folders)
    present = [c for c in tuple(option_names) if c in frame.columns]
    for i, rec in enumerate(frame.to_dict("records")):
        where = f"{name} row {i + 2}" if not name.lower().endswith(".parquet") else f"{name} row {i}"
        if _blank(rec["log"]):
            raise UsageError(f"{where}: the log cell is empty")
        log = str(rec["log"]).strip()
        log_path = log if os.path.isabs(log) else str(base / log)
        real = _confined(log_path, fence, root is None, f"{where}: {log}", folders)
        robot_id, stamp = id_and_time_from_path(log_path, id_pattern)
        source = "path" if stamp is not None else None
        if not _blank(rec.get("robot_id")):
            robot_id = str(rec["robot_id"]).strip()
        if not _blank(rec.get("time")):
            stamp, source = parse_time(rec["time"], f"{where}: time"), "manifest"
        robot = None if _blank(rec.get("robot")) else str(rec["robot"]).strip()
        if robot is not None:
            robot = _manifest_robot(robot, base, fence, root is None, f"{where}: robot {robot}", folders)
        opts = {c: _option_value(c, rec[c], f"{where}: {c}") for c in present if not _blank(rec[c])}
        entries.append(LogEntry(real, robot_id, robot, stamp, source, opts))
    if not entries:
        raise UsageError(f"{name}: the manifest lists no log")
    return entries


def _confined(
    log_path: str, fence: str, default_root: bool, where: str, folders: dict[str, str] | None = None,
    robot: bool = False,
) -> str:  # fmt: skip
    """The real path of a manifest's log, refused (UsageError naming ``where``) outside the folder ``fence`` or when
    it names something that is neither a file nor a folder (see :func:`read_manifest`).  ``folders``: the real
    paths of folders resolved so far (filled here).  ``robot``: a robot file, which a folder is not either."""
    thing = "robot file" if robot else "log"
    real = _realpath(log_path, folders if folders is not None else {})
    if real != fence and not real.startswith(fence.rstrip(os.sep) + os.sep):  # os.path.commonpath, 5x faster
        which = "the manifest's folder" if default_root else option("manifest_root")
        raise UsageError(
            f"{where}: resolves to {real}, outside {which} {fence}; a manifest reaches the logs and robot files "
            f"under its root only: move the {thing} there, or give {option('manifest_root')} a folder that holds "
            f"every {thing}"
        )
    kind = not_regular(real) or (LOOP if broken_link(real) == LOOP else None)  # a link to nothing: a missing log
    if kind is not None and (robot or kind != "a folder"):
        names = "a built-in robot or a robot file in its robot cells" if robot else "log files and rosbag2 folders"
        raise UsageError(f"{where}: {real} is {kind}, not a {thing}; a manifest names {names}")
    return real


def _manifest_robot(robot: str, base: Path, fence: str, default_root: bool, where: str, folders: dict[str, str]) -> str:
    """A manifest's robot cell: a built-in robot's name as it is; else a robot file, relative to the manifest as the
    logs are, resolved and kept inside the root, refused unless a regular file (:func:`_confined`: a FIFO named
    there hung the worker that loaded it; /etc/shadow was read as TOML).  A file that is not there is left to the
    worker to name."""
    # model.robot (~5 ms): only a manifest read (wmrid.fleets.run stays lazy)
    from wmrid.model.robot import BUILTIN_ROBOTS

    if robot in BUILTIN_ROBOTS:
        return robot
    return _confined(robot if os.path.isabs(robot) else str(base / robot), fence, default_root, where, folders, True)


def _realpath(path: str, folders: dict[str, str]) -> str:
    """``os.path.realpath(path)``, its folder's real path taken from ``folders`` when known (and added): the same
    result, since the folder's links are resolved before the last name is; a path with ``.`` or ``..`` in it, or
    whose last name is a link, is resolved whole."""
    head, tail = os.path.split(path)
    parts = path.split(os.sep)
    if not head or not tail or "." in parts or ".." in parts:
        return os.path.realpath(path)
    folder = folders.get(head)
    if folder is None:
        folder = folders[head] = os.path.realpath(head)
    candidate = os.path.join(folder, tail)
    return os.path.realpath(candidate) if os.path.islink(candidate) else candidate
