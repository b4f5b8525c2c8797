"""The table a fleet run (:func:`wmrid.fleets.run.fleet`) writes: this run's rows kept compactly (:class:`NewRows`),
merged with the rows of the table it resumes (:func:`merged`), that table read with what its rows make known
(:func:`resume_table`), and the rows of logs no worker identified (:func:`missing_row`, :func:`failed_row`).
"""

from __future__ import annotations

import os
from typing import Any

from wmrid import __version__
from wmrid.core.errors import OutputExistsError
from wmrid.fleets.table import canonical_options, empty_row, read_arrow, sort_table, to_arrow
from wmrid.fleets.worker import _one_line


class NewRows:
    """This run's rows, kept as Arrow tables of :data:`CHUNK` rows: about half a kilobyte a row in the client, not
    the few kilobytes of a dict, so a million logs fit."""

    CHUNK = 2048

    def __init__(self) -> None:
        self.chunks: list[Any] = []
        self.pending: list[dict[str, Any]] = []

    def add(self, row: dict[str, Any]) -> None:
        self.pending.append(row)
        if len(self.pending) >= self.CHUNK:
            self.chunks.append(to_arrow(self.pending))
            self.pending = []

    def table(self) -> Any:
        import pyarrow as pa  # pyarrow (extra [fleet]): only a table made

        return pa.concat_tables([*self.chunks, to_arrow(self.pending)])


def row_keys(table: Any) -> Any:
    """Each row's (log's real path, options key) as one string column: the same log named two ways is one log."""
    import pyarrow as pa  # pyarrow (extra [fleet]): only a run's rows keyed
    import pyarrow.compute as pc  # pyarrow: only a run's rows keyed

    real = pa.array([os.path.realpath(log) for log in table["log"].to_pylist()], pa.string())
    return pc.binary_join_element_wise(real, table["options_key"], "\x00")


def merged(old: Any, new: NewRows, old_keys: Any = None) -> Any:
    """The old table's rows that this run did not redo, and this run's, sorted (robot, time, log); ``old_keys``: the
    old table's :func:`row_keys`, computed once per run."""
    import pyarrow as pa  # pyarrow (extra [fleet]): only a run's rows merged
    import pyarrow.compute as pc  # pyarrow: only a run's rows merged

    fresh = new.table()
    if old is None:
        return sort_table(fresh)
    keep = pc.invert(pc.is_in(row_keys(old) if old_keys is None else old_keys, value_set=row_keys(fresh)))
    return sort_table(pa.concat_tables([old.filter(keep), fresh]))


def resume_table(
    out: str, specs: list[dict[str, Any]], resume: bool, retry_failed: bool, force: bool
) -> tuple[Any, list[dict[str, Any]], list[str]]:
    """(the old table or None, the specs, each with the content hash of its old row when that row is kept unless the
    log changed: ``known_sha256``, notes)."""
    exists = os.path.exists(out)
    if not resume:
        if exists and not force:
            raise OutputExistsError(
                f"{out} exists; give --resume to continue it (logs already in it are not run again) or --force to "
                "replace it"
            )
        return None, specs, []
    if not exists:
        return None, specs, [f"{out} does not exist yet: every log is identified"]
    old = read_arrow(out, as_input=False)  # read, then rewritten: not an input the output must differ from
    columns = old.select(["log", "options_key", "sha256", "error", "robot_id", "start_time", "time_source"])
    known = {}
    for log, key, sha, err, robot_id, start, source in zip(*columns.to_pydict().values(), strict=True):
        if sha and not (retry_failed and err is not None):
            known[(os.path.realpath(log), key)] = (sha, robot_id, start, source)
    for spec in specs:
        prev = known.get((os.path.realpath(spec["log"]), spec["options_key"]))
        if prev is None:
            continue
        sha, robot_id, start, source = prev
        renamed = robot_id != spec["robot_id"] or (spec["time"] is not None and start != spec["time"])
        if not renamed:  # a manifest that now says another robot or time: identified again, to carry them
            spec["known_sha256"] = sha  # the worker hashes; the same content is not identified again
    return old, specs, []


def missing_row(spec: dict[str, Any]) -> dict[str, Any]:
    """The row of a log that does not exist: its error as :func:`~wmrid.fleets.worker.identify_entry` would say it."""
    return empty_row(
        robot_id=spec["robot_id"], log=spec["log"], robot=spec.get("robot"), start_time=spec.get("time"),
        time_source=spec.get("time_source"), options=canonical_options(spec["options"]),
        options_key=spec["options_key"], error=f"{spec['log']}: cannot be read (No such file or directory)",
        run_time_s=0.0, wmrid_version=__version__,
    )  # fmt: skip


def failed_row(spec: dict[str, Any], err: BaseException) -> dict[str, Any]:
    """The row of a log whose task never ran to its end (its workers died, or it was cancelled): ``err`` said."""
    return empty_row(
        robot_id=spec["robot_id"], log=spec["log"], robot=spec.get("robot"), start_time=spec.get("time"),
        time_source=spec.get("time_source"), options=canonical_options(spec["options"]),
        options_key=spec["options_key"],
        error=f"{spec['log']}: the task failed on the cluster ({type(err).__name__}: {_one_line(err)})",
    )  # fmt: skip
