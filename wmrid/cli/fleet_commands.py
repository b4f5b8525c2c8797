"""``wmrid fleet`` and ``wmrid fleet-report``: each a translation of its flags into one library call
(:mod:`wmrid.fleets.run`, :mod:`wmrid.fleets.report`) and a rendering of the outcome.

Imports inside functions: start-up time (``wmrid --help`` and each command load only what that command runs).
"""

from __future__ import annotations

import json
import sys
from dataclasses import fields
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from wmrid.cli.app import app, invocation
from wmrid.cli.groups import FIT_FLAGS, LOG_FLAGS, OBSERVER_FLAGS, takes
from wmrid.cli.help import Command
from wmrid.cli.helpers import activity, stderr_console
from wmrid.cli.options import (
    MethodChoice,
    MethodOpt,
    OutputFormat,
    RotorInertiaOpt,
)
from wmrid.core.errors import ExitStatus, UsageError
from wmrid.reporting.terminal import console

if TYPE_CHECKING:
    from wmrid.api.inputs import LogOptions
    from wmrid.estimators.options import MethodOptions, ObserverOptions


_RUN_PANEL = "The fleet run"


def _given_options(
    log_options: LogOptions, observer: ObserverOptions, fit: MethodOptions, method: str, rotor_inertia: float | None
) -> dict[str, Any]:
    """identify's settings as ``wmrid fleet`` passes them, by their Python names: only those given a value other
    than the default, so that the table's "options" column says what was asked and nothing else."""
    from wmrid.api.inputs import LogOptions
    from wmrid.estimators.options import FIT_NAMES, MethodOptions, ObserverOptions

    given: dict[str, Any] = {}
    for options, plain in ((log_options, LogOptions()), (observer, ObserverOptions())):
        given.update({f.name: getattr(options, f.name) for f in fields(options)
                      if getattr(options, f.name) != getattr(plain, f.name)})  # fmt: skip
    plain_fit = MethodOptions()
    given.update({name: getattr(fit, field) for name, field in FIT_NAMES.items()
                  if getattr(fit, field) != getattr(plain_fit, field)})  # fmt: skip
    if method != "auto":
        given["method"] = method
    if rotor_inertia is not None:
        given["rotor_inertia"] = rotor_inertia
    return given


@app.command(
    cls=Command,
    name="fleet",
    epilog="Examples:\n\n"
    "wmrid fleet logs/ --robot paper -o fleet.parquet\n\n"
    "wmrid fleet --manifest fleet.csv -o fleet.parquet --resume\n\n"
    "wmrid fleet 'logs/*/*.mcap' --scheduler tcp://10.0.0.5:8786 -o fleet.parquet",
)
@takes(LOG_FLAGS, OBSERVER_FLAGS, FIT_FLAGS)
def fleet_command(
    logs: Annotated[
        list[str] | None,
        typer.Argument(
            metavar="LOG",
            help="Logs: files, globs (quoted, ** recursive) or folders (searched for logs; a rosbag2 folder is one "
            "log).  Or give --manifest.",
            show_default=False,
        ),
    ] = None,
    output: Annotated[
        Path | None,
        typer.Option(
            "--output", "-o", help="The table to write: Parquet, one row per log (required).", show_default=False
        ),
    ] = None,
    manifest: Annotated[
        Path | None,
        typer.Option(
            help="CSV or Parquet, one row per log: log (relative to the manifest), robot_id, robot, time, and any "
            "identify option by its Python name (speed_unit, columns, method, ...).  Each log must resolve inside "
            "--manifest-root and be a file or rosbag2 folder; a robot cell is a built-in name or a robot file "
            "there.",
            rich_help_panel=_RUN_PANEL,
        ),
    ] = None,
    manifest_root: Annotated[
        Path | None,
        typer.Option(
            help="The folder every log and robot file of --manifest must resolve into, links and .. followed (a row "
            "outside it, or naming a device, FIFO or loop of links, is refused).  [default: the manifest's folder]",
            show_default=False,
            rich_help_panel=_RUN_PANEL,
        ),
    ] = None,
    id_pattern: Annotated[
        str | None,
        typer.Option(
            help="Regular expression with (?P<robot>...) and optionally (?P<time>...) groups, searched in each "
            "log's path; default: the robot id is the log's folder name, the time a date in its file name.",
            rich_help_panel=_RUN_PANEL,
        ),
    ] = None,
    scheduler: Annotated[
        str,
        typer.Option(
            help="local: a LocalCluster of one worker process per core; or an existing Dask scheduler's address "
            "(tcp://HOST:8786).",
            rich_help_panel=_RUN_PANEL,
        ),
    ] = "local",
    workers: Annotated[
        int | None,
        typer.Option(
            help="--scheduler local: worker processes, >= 1 (default: one per core).", rich_help_panel=_RUN_PANEL
        ),
    ] = None,
    resume: Annotated[
        bool,
        typer.Option(
            "--resume",
            help="Continue the table: a log whose content hash and options equal a row's is not identified again.",
            rich_help_panel=_RUN_PANEL,
        ),
    ] = False,
    retry_failed: Annotated[
        bool,
        typer.Option(
            "--retry-failed", help="With --resume: also re-run the rows with an error.", rich_help_panel=_RUN_PANEL
        ),
    ] = False,
    no_fit: Annotated[
        bool,
        typer.Option(
            "--no-fit",
            help="Leave fit_r/fit_l empty (they simulate the identified model on each log: about a third of the "
            "time per log).",
            rich_help_panel=_RUN_PANEL,
        ),
    ] = False,
    batch: Annotated[
        int | None,
        typer.Option(
            help="Logs per Dask task, >= 1 (default: about 32 tasks per worker, at most 16 logs each): the "
            "scheduler's work per task is shared by this many logs.",
            rich_help_panel=_RUN_PANEL,
        ),
    ] = None,
    checkpoint: Annotated[
        float,
        typer.Option(
            help="Seconds between writes of the table while the run goes on, in (0, inf] (inf: at the end only).",
            rich_help_panel=_RUN_PANEL,
        ),
    ] = 60.0,
    force: Annotated[bool, typer.Option("--force", help="Replace an existing table (else: --resume).")] = False,
    output_format: Annotated[
        OutputFormat, typer.Option("--format", help="Summary: table, json, or auto (table on a terminal).")
    ] = OutputFormat.auto,
    robot: Annotated[
        str | None,
        typer.Option(help="Robot of every log whose manifest row names none: built-in name, TOML or URDF file."),
    ] = None,
    rotor_inertia: RotorInertiaOpt = None,
    method: MethodOpt = MethodChoice.auto,
    *,
    log_options: LogOptions,
    observer: ObserverOptions,
    fit: MethodOptions,
) -> int:
    """Identify every log of a fleet on Dask and write one Parquet table, one row per log: robot id, log, content
    hash, start time, duration, samples, method, every base parameter with its std, flags, warnings, fit, run time,
    and the error of a log that failed (a failed log never ends the run)."""
    from wmrid.core.extras import require_installed

    require_installed("distributed", "fleet")  # before the fleet's modules, which import pyarrow
    require_installed("pyarrow", "fleet")
    if output is None:
        raise UsageError("-o/--output is required: the Parquet table to write (e.g. -o fleet.parquet)")
    from wmrid.fleets.run import fleet as run_fleet

    given = _given_options(log_options, observer, fit, method.value, rotor_inertia)
    update, finish = _progress()
    try:
        run = run_fleet(
            logs or (), output, manifest=manifest, manifest_root=manifest_root, robot=robot, id_pattern=id_pattern,
            scheduler=scheduler, workers=workers, resume=resume, retry_failed=retry_failed, force=force, fit=not no_fit,
            batch=batch, checkpoint=checkpoint, progress=update, **given,
        )  # fmt: skip
    except KeyboardInterrupt:
        finish()
        sys.stderr.write("wmrid: fleet: the same command with --resume continues where this one stopped\n")
        raise
    finally:
        finish()
    summary = _summary(run, output)
    fmt = output_format.value
    if fmt == "auto":
        fmt = "table" if sys.stdout.isatty() else "json"
    if fmt == "json":
        sys.stdout.write(json.dumps(summary, indent=2) + "\n")
    else:
        _print_summary(summary)
    rows = summary["logs"]
    if summary["failed"]:  # said on stderr too: the summary may go to a file or a pipe
        first = " ".join(str(summary["errors"][0]["error"]).split()) if summary["errors"] else "?"
        sys.stderr.write(
            f"wmrid: {summary['failed']} of {rows} logs failed (each one's error is in the table's error column); "
            f"the first: {first}\n"
        )
    return int(ExitStatus.OK) if summary["failed"] < rows or not rows else int(ExitStatus.NO_RESULT)


def _progress():
    """(callback(done, total, failed), finish): a progress bar on stderr when it is a terminal."""
    if not sys.stderr.isatty():
        return None, lambda: None
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    bar = Progress(
        TextColumn("fleet"), BarColumn(), MofNCompleteColumn(), TextColumn("logs, {task.fields[failed]} failed"),
        TimeRemainingColumn(), console=stderr_console(), transient=True,
    )  # fmt: skip
    state: dict[str, Any] = {}

    def update(done: int, total: int, failed: int) -> None:
        if not state:
            state["task"] = bar.add_task("fleet", total=total, failed=0)
            bar.start()
        bar.update(state["task"], completed=done, failed=failed)

    def finish() -> None:
        if state.pop("task", None) is not None:
            bar.stop()

    return update, finish


def _summary(run: Any, output: Path) -> dict[str, Any]:
    import pyarrow.compute as pc

    table = run.table
    failed = table.filter(pc.is_valid(table["error"])).select(["log", "error"])
    errors = failed.slice(0, 100).to_pylist()  # the first 100; the table has them all
    rate = run.identified / run.wall_s if run.wall_s > 0 else None
    # "run": the logs this run tried (FleetRun.identified); "identified": those of them that gave a result (a run of
    # 1 log that failed said "identified 1, failed 1"); "failed": every row of the table with an error
    return {
        "table": str(output), "logs": table.num_rows, "robots": pc.count_distinct(table["robot_id"]).as_py(),
        "run": run.identified, "identified": run.identified - run.failed, "resumed": run.skipped,
        "failed": failed.num_rows, "workers": run.workers,
        "scheduler": run.scheduler, "wall_s": round(run.wall_s, 3), "logs_per_s": rate, "errors": errors,
        "notes": run.notes, "command": invocation(),
    }  # fmt: skip


def _print_summary(summary: dict[str, Any]) -> None:
    out = console()
    rate = f", {summary['logs_per_s']:.3g} logs/s" if summary["logs_per_s"] else ""

    def n(count: int, noun: str) -> str:
        return f"{count} {noun}" + ("" if count == 1 else "s")

    out.print(
        f"{summary['table']}: {n(summary['logs'], 'log')} of {n(summary['robots'], 'robot')}; run "
        f"{summary['run']} in {summary['wall_s']:.3g} s on {n(summary['workers'], 'worker')}{rate}, identified "
        f"{summary['identified']}; resumed {summary['resumed']}; failed {summary['failed']}"
    )
    for note in summary["notes"]:
        out.print(f"note: {note}")
    for err in summary["errors"][:10]:
        out.print(f"failed: {err['error']}")
    if summary["failed"] > 10:
        out.print(f"... and {summary['failed'] - 10} more failed logs (the table's error column)")


@app.command(
    cls=Command,
    name="fleet-report",
    epilog="Examples:\n\n"
    "wmrid fleet-report fleet.parquet -o fleet.html\n\n"
    "wmrid fleet-report fleet.parquet --robot paper --alpha 0.0001 -o fleet.json",
)
def fleet_report_command(
    table: Annotated[str, typer.Argument(metavar="TABLE", help="The Parquet table of `wmrid fleet`.")],
    output: Annotated[
        Path | None,
        typer.Option("--output", "-o", help="Write the report: .html (self-contained), .md or .json."),
    ] = None,
    robot: Annotated[
        str | None,
        typer.Option(help="Robot of the rows without one (name, TOML or URDF): its r and b give payload estimates."),
    ] = None,
    baseline: Annotated[
        int, typer.Option(help="Logs of each robot that are its own reference, >= 5 (the first ones).")
    ] = 10,
    window: Annotated[int, typer.Option(help="A change is sought starting within the last this many logs, >= 1.")] = 30,
    alpha: Annotated[
        float,
        typer.Option(
            help="False-alarm rate: probability that a robot whose parameters do not change is flagged over its "
            "history, in [1e-09, 0.2]."
        ),
    ] = 0.001,
    outlier_alpha: Annotated[
        float,
        typer.Option(
            help="Probability that any robot of a model with Gaussian unit-to-unit spread is said to stand out, in "
            "[1e-09, 0.2]."
        ),
    ] = 0.001,
    output_format: Annotated[
        OutputFormat, typer.Option("--format", help="Without -o: table, json, or auto (table on a terminal).")
    ] = OutputFormat.auto,
    force: Annotated[bool, typer.Option("--force", help="Overwrite an existing output file.")] = False,
) -> None:
    """Review a fleet table: per robot, every base parameter over time with ±2σ bands; changes across its logs
    (friction rising: wheel wear?; M or Vc shifting: payload or configuration change) at a stated false-alarm rate;
    robots that stand out from their fleet; the robots ranked by the evidence against them."""
    from wmrid.core.extras import require_installed

    require_installed("pyarrow", "fleet", "wmrid fleet-report")  # imported by the review, after the checks below
    from wmrid.cli.helpers import check_outputs

    check_outputs((output,), force, (table,))  # before anything is imported or read
    from wmrid.api.reporting import REPORT_SUFFIXES
    from wmrid.fleets.rendering import ranked_table, to_json_dict
    from wmrid.fleets.report import check_settings, fleet_report as build, write_fleet_report

    suffix = output.suffix.lower() if output is not None else None
    if suffix not in (None, *REPORT_SUFFIXES):
        raise UsageError(f"-o {output}: the report format comes from the suffix: .html, .md or .json")
    check_settings(baseline, window, alpha, outlier_alpha)
    with activity("wmrid fleet-report") as stage:
        stage("reviewing the table")
        rep = build(
            table, robot=robot, baseline=baseline, window=window, alpha=alpha, outlier_alpha=outlier_alpha,
            figures=suffix in (".html", ".htm", ".md"), command=invocation(),
        )  # fmt: skip
        if output is not None:
            stage(f"writing {output}")
            write_fleet_report(rep, output, force=force)
    if output is not None:
        stderr_console().print(f"wrote {output}")
        return
    fmt = output_format.value
    if fmt == "auto":
        fmt = "table" if sys.stdout.isatty() else "json"
    if fmt == "json":
        sys.stdout.write(json.dumps(to_json_dict(rep), indent=2, default=str) + "\n")
        return
    from wmrid.reporting.terminal import print_table

    out = console()
    for line in rep.summary:
        out.print(line)
    ranked = ranked_table(rep.review)
    rows = [[str(c) for c in row[1:]] for row in ranked.rows]  # the rank is the order
    print_table(
        out, ranked.header[1:], rows, title="Robots ranked by the evidence against them", numeric=(3,), fold=(1, 4)
    )
    for rv in rep.review.robots:
        for finding in rv.findings:
            out.print(f"{rv.robot_id}: {finding}")
