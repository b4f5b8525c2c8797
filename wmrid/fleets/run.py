"""A fleet's logs identified on a Dask cluster: :func:`fleet` runs ``identify`` on every log (one task per log) and
writes one row per log to a Parquet table (:mod:`wmrid.fleets.table`).

The same code path serves a LocalCluster started here (``scheduler="local"``: one single-threaded worker process per
core) and an existing cluster (``scheduler="tcp://host:8786"``, whose workers have wmrid installed).  A log that
fails is a row with its error; a worker that dies has its tasks retried by the scheduler (``allowed-failures``), and
a log that kills three workers is a row with that error.  At most ``window`` tasks are in flight, so the client and
the scheduler hold a bounded number of tasks whatever the fleet's size; the table is written atomically every
``checkpoint`` seconds and at the end (also on Ctrl-C), so ``resume=True`` continues an interrupted run: a log
whose content hash and options equal a row's is not identified again.

Imports inside functions: start-up time (a front door: ``import wmrid`` and each function load only what that
function uses).
"""

from __future__ import annotations

import contextlib
import itertools
import os
import time
import uuid
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

from wmrid.core.errors import UsageError, option
from wmrid.estimators.options import SETTING_NAMES
from wmrid.fleets.manifest import read_manifest
from wmrid.fleets.run_table import NewRows, failed_row, merged, missing_row, resume_table, row_keys
from wmrid.fleets.table import (
    LogEntry,
    content_digest,
    entries_from_paths,
    options_key,
    write_table,
)
from wmrid.fleets.worker import _one_line, _split_options, identify_batch, warm_up

__all__ = ["FleetRun", "fleet", "option_columns"]

#: identify's keywords a manifest row may set, besides the :class:`~wmrid.api.inputs.LogOptions` fields: its
#: settings (the method, the observer's options, the classical methods') and the rotor inertia.
IDENTIFY_OPTIONS = (*SETTING_NAMES, "rotor_inertia")


def option_columns() -> tuple[str, ...]:
    """The per-log options a manifest may give (and ``fleet``'s keywords): identify's settings and the log
    options, by their Python names."""
    from wmrid.api.inputs import LOG_OPTION_NAMES

    return IDENTIFY_OPTIONS + LOG_OPTION_NAMES


@dataclass
class FleetRun:
    """What :func:`fleet` did.

    Attributes
    ----------
    table
        The table written (a pyarrow Table; old rows kept by ``resume`` included); :attr:`rows` gives the same as
        dicts.
    identified
        The logs identified in this run.
    skipped
        The logs resumed from the table.
    failed
        The rows of this run with an error.
    wall_s
        s, the run's wall time.
    startup_s
        s to start (or reach) the cluster and its workers.
    processing_s
        s from then to the last result.
    client_cpu_s
        CPU seconds of this process (the client, and the scheduler of a LocalCluster) while processing.
    workers
        The cluster's worker count.
    scheduler
        The cluster's address.
    notes
        What the run said about itself, a sentence each (e.g. a table to resume that did not exist yet).
    """

    table: Any = None
    identified: int = 0
    skipped: int = 0
    failed: int = 0
    wall_s: float = 0.0
    #: seconds to start (or reach) the cluster and its workers; seconds from then to the last result
    startup_s: float = 0.0
    processing_s: float = 0.0
    #: CPU seconds of this process (the client, and the scheduler of a LocalCluster) while processing
    client_cpu_s: float = 0.0
    workers: int = 0
    scheduler: str = ""
    notes: list[str] = field(default_factory=list)

    @property
    def rows(self) -> list[dict[str, Any]]:
        """The table's rows as dicts (as :func:`~wmrid.fleets.table.read_table` gives them)."""
        return [] if self.table is None else self.table.to_pylist()


# ------------------------------------------------------------------------------------------------------------------
# The fleet, on the client


def _robot_digest(robot: str | None, cache: dict[str, str | None]) -> str | None:
    """SHA-256 of a robot file (None for a built-in name), so that a changed robot file re-runs its logs."""
    if robot is None:
        return None
    if robot not in cache:
        cache[robot] = content_digest(robot)[0] if os.path.isfile(robot) else None
    return cache[robot]


def _check_payload_robots(specs: Sequence[dict[str, Any]]) -> None:
    """A payload asked for (run-wide or in a manifest row) needs the unloaded robot it is weighed against: a log to
    run without a robot is one error before any worker starts, not a failed row per log (the logs a resumed table
    keeps are not asked again)."""
    for spec in specs:
        if spec["options"].get("payload") is True and not spec["robot"]:
            where = f"{spec['log']}: " if len(specs) > 1 else ""
            raise UsageError(
                f"{where}{option('payload')} estimates the payload against the unloaded robot: give {option('robot')} "
                "(or a robot column in the manifest)"
            )


def check_defaults(defaults: dict[str, Any]) -> dict[str, Any]:
    """The run-wide options (identify's keywords and LogOptions fields, None = not given), checked as ``identify``
    checks them before any log is read."""
    from wmrid.api.identification import check_rotor_inertia, settings_from
    from wmrid.api.inputs import LogOptions

    allowed = set(option_columns())
    unknown = sorted(set(defaults) - allowed)
    if unknown:
        raise UsageError(f"not options of identify: {', '.join(unknown)}")
    given = {k: v for k, v in defaults.items() if v is not None}
    log_opts, run_opts = _split_options(given)
    LogOptions(**log_opts)
    check_rotor_inertia(run_opts.pop("rotor_inertia", None))
    settings_from(run_opts)
    if run_opts.get("method", "auto") != "auto":
        # the methods (their numba kernels, ~0.3 s to import): only when one is named, not before every manifest read
        from wmrid.estimators.methods import check_method

        check_method(run_opts["method"])
    return given


def plan(entries: Sequence[LogEntry], defaults: dict[str, Any], robot: str | None, fit: bool) -> list[dict[str, Any]]:
    """One task spec per log (see :func:`identify_entry`): the run-wide options under each manifest row's own."""
    digests: dict[str, str | None] = {}
    specs = []
    for e in entries:
        opts = {**defaults, **e.options}
        robot_ = e.robot or robot
        keyed = {**opts, "robot": robot_, "robot_sha256": _robot_digest(robot_, digests), "fit": fit}
        specs.append({
            "log": e.log, "robot_id": e.robot_id, "robot": robot_, "time": e.time, "time_source": e.time_source,
            "options": opts, "options_key": options_key(keyed), "fit": fit, "known_sha256": None,
        })  # fmt: skip
    return specs


@contextlib.contextmanager
def dask_client(scheduler: str, workers: int | None = None) -> Iterator[Any]:
    """A ``distributed.Client``: on a LocalCluster of ``workers`` single-threaded worker processes (default: one per
    core) for ``scheduler="local"``, else connected to the scheduler at that address."""
    import logging

    from wmrid.core.extras import require

    require("distributed", "fleet")
    from distributed import Client, LocalCluster

    if scheduler == "local":
        n = workers or os.cpu_count() or 1
        cluster = LocalCluster(
            n_workers=n, threads_per_worker=1, processes=True, silence_logs=logging.ERROR,
            dashboard_address="127.0.0.1:0",  # a free port: two runs at once never fight over 8787
        )  # fmt: skip
        try:
            with Client(cluster) as client:
                yield client
        finally:
            cluster.close()
        return
    if workers is not None:
        raise UsageError(f"{option('workers')} starts a local cluster; an existing cluster has its own workers")
    try:
        client = Client(scheduler, timeout=30)
    except (OSError, TimeoutError, ValueError) as err:
        raise UsageError(
            f"{option('scheduler', scheduler)}: no Dask scheduler answers there ({_one_line(err)}); start one with "
            "`dask scheduler` and `dask worker ADDRESS`, or use --scheduler local"
        ) from None
    try:
        yield client
    finally:
        client.close()


def fleet(
    logs: Sequence[str] = (),
    output: str | os.PathLike[str] | None = None,
    *,
    manifest: str | os.PathLike[str] | None = None,
    manifest_root: str | os.PathLike[str] | None = None,
    robot: str | None = None,
    id_pattern: str | None = None,
    scheduler: str = "local",
    workers: int | None = None,
    resume: bool = False,
    retry_failed: bool = False,
    force: bool = False,
    fit: bool = True,
    window: int | None = None,
    batch: int | None = None,
    checkpoint: float = 60.0,
    progress: Callable[[int, int, int], None] | None = None,
    **defaults: Any,
) -> FleetRun:
    """Identify every log of a fleet on Dask and write the table (Parquet) to ``output``.

    One task identifies a batch of logs; a log that fails is a row with its error.  The table is written atomically
    every ``checkpoint`` seconds and at the end (also on Ctrl-C), so that ``resume=True`` continues an interrupted
    run.

    Parameters
    ----------
    logs
        Paths, globs or folders (:func:`~wmrid.fleets.table.find_logs`); give these or ``manifest``.  Robot id and
        time of a log without them come from ``id_pattern`` or the path's folder and date
        (:func:`~wmrid.fleets.table.id_and_time_from_path`), else the log's own first stamp when it is an epoch
        time.
    output
        The Parquet table to write (required; named ``.parquet``).
    manifest
        A CSV or Parquet file, one row per log (:func:`~wmrid.fleets.manifest.read_manifest`), instead of ``logs``.
    manifest_root
        The folder every log of the manifest must resolve into (default: the manifest's own folder); a row outside
        it, or naming a device or a FIFO, is refused (UsageError naming the row).
    robot
        The robot file or built-in name of every log whose manifest row names none.
    id_pattern
        A regular expression searched in a log's path, with a named group ``robot`` and optionally ``time``: the
        robot id and time of a log without them (None: the path's folder and date).
    scheduler
        "local" (a LocalCluster of ``workers`` processes) or a scheduler address (``"tcp://host:8786"``, whose
        workers have wmrid installed).
    workers
        The LocalCluster's worker processes, >= 1 (None: one per core).
    resume
        Keep the rows of an existing table whose log, content hash and options are unchanged (not identified
        again).
    retry_failed
        With ``resume``, also re-run the table's error rows.
    force
        Overwrite an existing table (needed without ``resume``).
    fit
        Also compute each log's fit % (fit_r, fit_l): the model's simulated speeds on the log itself.
    window
        Tasks in flight at most (None: 8 per worker).
    batch
        Logs per task, >= 1 (None: :func:`auto_batch`: the scheduler's and client's work per task is shared by
        ``batch`` logs).
    checkpoint
        s between table writes, > 0.
    progress
        Called as ``progress(done, total, failed)``.
    **defaults
        identify's keywords and :class:`~wmrid.api.inputs.LogOptions` fields for every log (a manifest row's own
        options win).

    Returns
    -------
    FleetRun
        What the run did, with the table written.

    Raises
    ------
    UsageError
        No ``output`` or one not named .parquet, a setting out of range, both or neither of ``logs`` and
        ``manifest``, ``manifest_root`` without ``manifest``, or no Dask scheduler at ``scheduler``.
    OutputExistsError
        The table exists and neither ``resume`` nor ``force`` is given.
    """
    from wmrid.core.extras import require_installed
    from wmrid.core.jit import warn_plain_python
    from wmrid.runtime.atomic import register_input

    require_installed("distributed", "fleet")  # imported only when the cluster starts: a bad manifest is said first
    require_installed("pyarrow", "fleet")
    warn_plain_python("every log is identified")  # once here: the workers keep theirs to themselves
    if output is None:
        raise UsageError(f"{option('output')} is required: the Parquet table to write (e.g. fleet.parquet)")
    out = os.fspath(output)
    if not out.lower().endswith(".parquet"):
        raise UsageError(f"{option('output', out)}: the fleet table is Parquet; name it .parquet")
    if workers is not None and (isinstance(workers, bool) or workers < 1):
        raise UsageError(f"{option('workers')} must be >= 1, got {workers}")
    if batch is not None and (isinstance(batch, bool) or not isinstance(batch, int) or batch < 1):
        raise UsageError(f"{option('batch')} must be a whole number >= 1, got {batch!r}")
    if not (checkpoint > 0):
        raise UsageError(f"{option('checkpoint')} must be > 0 seconds, got {checkpoint}")
    if bool(logs) == (manifest is not None):
        raise UsageError(f"give the logs or {option('manifest')}, one of the two")
    given = check_defaults(defaults)
    if manifest_root is not None and manifest is None:
        raise UsageError(f"{option('manifest_root')} applies to {option('manifest')} only")
    if manifest is not None:
        entries = read_manifest(manifest, id_pattern, option_columns(), root=manifest_root)
    else:
        entries = entries_from_paths(logs, id_pattern)
    seen: set[str] = set()
    unique = []
    for e in entries:  # a log named twice (a manifest's repeated row, a folder and its file) is identified once
        key = e.log if manifest is not None else os.path.realpath(e.log)  # a manifest's logs are real paths already
        if key not in seen:
            seen.add(key)
            unique.append(e)
    entries = unique
    for e in entries:
        register_input(e.log)  # the table is never written over a log
    if robot is not None:
        from wmrid.api.inputs import load_robot

        load_robot(robot, gear_ratio=given.get("gear_ratio"))  # a bad robot file is one error, not a row per log
    specs = plan(entries, given, robot, fit)
    old, specs, notes = resume_table(out, specs, resume, retry_failed, force)
    _check_payload_robots(specs)
    run = FleetRun(notes=notes, scheduler=scheduler)
    started = time.perf_counter()
    new_rows = NewRows()
    old_keys = None if old is None else row_keys(old)
    running = False
    # A log that is not there is its row's error at once, as a worker would write it, but without a task: 10^5 rows
    # of a manifest naming no log took 49 s of the cluster's time (issue 30).
    there = [os.path.exists(spec["log"]) for spec in specs]
    missing = [spec for spec, ok in zip(specs, there, strict=True) if not ok]
    if missing:
        specs = [spec for spec, ok in zip(specs, there, strict=True) if ok]
        for spec in missing:
            new_rows.add(missing_row(spec))
        run.identified += len(missing)
        run.failed += len(missing)
        if progress is not None:
            progress(len(missing), len(missing) + len(specs), len(missing))
    try:
        if specs:
            with dask_client(scheduler, workers) as client:
                run.workers = _worker_count(client)
                client.run(warm_up)  # every worker loads the kernels now, not on its first log
                run.scheduler = client.scheduler.address if client.scheduler is not None else scheduler
                running = True
                last_write = ready = time.perf_counter()
                cpu = time.process_time()
                run.startup_s = ready - started
                size = batch or auto_batch(len(specs), run.workers)
                tasks = _run_tasks(client, specs, window or 8 * max(run.workers, 1), progress, size)
                for row in tasks:
                    if row.get("skipped"):
                        run.skipped += 1
                        continue
                    new_rows.add(row)
                    run.identified += 1
                    run.failed += row["error"] is not None
                    if time.perf_counter() - last_write >= checkpoint:
                        write_table(merged(old, new_rows, old_keys), out, force=True)
                        last_write = time.perf_counter()
                run.processing_s = time.perf_counter() - ready
                run.client_cpu_s = time.process_time() - cpu
    finally:  # Ctrl-C, a lost scheduler: what is done is kept, and --resume continues from it
        run.table = merged(old, new_rows, old_keys)
        if running or not specs:
            write_table(run.table, out, force=True)  # an existing table without --resume/--force was refused above
    run.wall_s = time.perf_counter() - started
    return run


def auto_batch(logs: int, workers: int) -> int:
    """Logs per task when not given: enough that each worker gets about 32 tasks, at most 16 logs: the scheduler's
    and client's work per task (a few ms of CPU, bench/speed/bench_fleet.py) is then shared, and the last tasks still
    balance across the workers."""
    return max(1, min(16, logs // (32 * max(workers, 1))))


def _worker_count(client: Any) -> int:
    """The cluster's workers, waiting up to a minute for the first."""
    count = len(client.scheduler_info().get("workers", {}))
    if count == 0:
        try:
            client.wait_for_workers(1, timeout=60)
        except (TimeoutError, OSError) as err:
            raise UsageError(
                f"the Dask scheduler has no worker after 60 s ({_one_line(err)}); start `dask worker`"
            ) from None
        count = len(client.scheduler_info().get("workers", {}))
    return count


def _run_tasks(
    client: Any,
    specs: list[dict[str, Any]],
    window: int,
    progress: Callable[[int, int, int], None] | None,
    batch: int = 1,
) -> Iterator[dict[str, Any]]:
    """The rows of ``specs`` as their tasks (``batch`` logs each) finish, at most ``window`` tasks in flight."""
    from distributed import as_completed

    token = uuid.uuid4().hex[:12]
    total, done, failed = len(specs), 0, 0
    groups = iter(enumerate(specs[i : i + batch] for i in range(0, len(specs), batch)))
    group_of: dict[Any, list[dict[str, Any]]] = {}

    def submit(i: int, group: list[dict[str, Any]]) -> Any:
        future = client.submit(identify_batch, group, pure=False, key=f"wmrid-identify-{token}-{i}")
        group_of[future] = group
        return future

    queue = as_completed([submit(i, g) for i, g in itertools.islice(groups, window)])
    for future in queue:
        group = group_of.pop(future)
        if future.status == "finished":
            rows = future.result()
        else:  # the task never ran to its end: its workers died (KilledWorker) or it was cancelled
            try:
                err = future.exception()
            except Exception as lost:  # a cancelled future has no exception to give: the cancellation is it
                err = lost
            rows = [failed_row(spec, err) for spec in group]
        future.release()
        nxt = next(groups, None)
        if nxt is not None:
            queue.add(submit(*nxt))
        for row in rows:
            if not row.get("skipped"):
                failed += row["error"] is not None
            done += 1
            if progress is not None:
                progress(done, total, failed)
            yield row
