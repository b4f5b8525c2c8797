"""``wmrid live``: a translation of its flags into one library call (:func:`wmrid.api.live.live`), the updates shown
as they come (a live table on a terminal, JSON lines in a pipe), the result written at the end and on a stop.

Imports inside functions: start-up time (``wmrid --help`` and each command load only what that command runs).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from wmrid.cli.app import app
from wmrid.cli.groups import LOG_FLAGS, OBSERVER_FLAGS, takes
from wmrid.cli.help import Command
from wmrid.cli.helpers import check_outputs, on_stdout, warning_summary
from wmrid.cli.options import (
    OutputFormat,
    RotorInertiaOpt,
)
from wmrid.reporting.terminal import console

if TYPE_CHECKING:
    from wmrid.api.inputs import LogOptions
    from wmrid.estimators.options import ObserverOptions


_LIVE_PANEL = "Live (refresh and when to stop)"


@app.command(
    cls=Command,
    name="live",
    epilog="Examples:\n\n"
    "wmrid live ws://robot.local:8765 --robot paper -o result.json  (foxglove_bridge on the robot)\n\n"
    "ros2 bag record -s mcap -o run /joint_states & wmrid live run/ --robot paper -o result.json\n\n"
    "wmrid live run.mcap --idle 5 --until-std 1 --params m11,m22,Vc\n\n"
    "some_logger | wmrid live - --columns t=time,eta_r=vr,eta_l=vl,tau_r=ur,tau_l=ul | jq .parameters",
)
@takes(LOG_FLAGS, OBSERVER_FLAGS)
def live_command(
    source: Annotated[
        str,
        typer.Argument(
            metavar="SOURCE",
            help="What is being written: ws://HOST:PORT (a Foxglove WebSocket server: foxglove_bridge), - (standard "
            "input: CSV rows with a header, JSON lines, or MCAP), a CSV file being appended to, an .mcap file being "
            "written, or a rosbag2 folder recorded with MCAP storage.",
        ),
    ],
    robot: Annotated[
        str | None,
        typer.Option(
            help="Robot: built-in name ('paper'), TOML file, or URDF (with --gear-ratio); starts the estimate."
        ),
    ] = None,
    every: Annotated[float, typer.Option(help="Seconds between refreshes, > 0.", rich_help_panel=_LIVE_PANEL)] = 1.0,
    idle: Annotated[
        float | None,
        typer.Option(
            help="End after this many seconds without new data (once samples have come), > 0 (default: wait).",
            rich_help_panel=_LIVE_PANEL,
        ),
    ] = None,
    until: Annotated[
        float | None,
        typer.Option(help="End after this many seconds of log time, > 0.", rich_help_panel=_LIVE_PANEL),
    ] = None,
    until_std: Annotated[
        float | None,
        typer.Option(
            "--until-std",
            metavar="PCT",
            help="End once every --params parameter's live relative std is below PCT percent, > 0.",
            rich_help_panel=_LIVE_PANEL,
        ),
    ] = None,
    params: Annotated[
        str | None,
        typer.Option(
            help="Comma-separated parameters --until-std watches (default: m11,m12,m22,Vc,Fv1,Fv2,Fd1,Fd2).",
            rich_help_panel=_LIVE_PANEL,
        ),
    ] = None,
    reconnect: Annotated[
        bool,
        typer.Option(
            "--reconnect",
            help="ws:// source: when the connection is lost, retry with back-off (else the run ends, exit 1, keeping "
            "what came).",
            rich_help_panel=_LIVE_PANEL,
        ),
    ] = False,
    monitor: Annotated[
        Path | None,
        typer.Option(
            "--monitor",
            metavar="MODEL.json",
            help="Watch the stream for a change against this identified model (wmrid monitor's test): an alarm line "
            '(a JSON line with "event": "change" in a pipe) with what moved and, for a payload, its mass (with '
            "--robot).",
            rich_help_panel=_LIVE_PANEL,
        ),
    ] = None,
    output: Annotated[
        Path | None,
        typer.Option(
            "--output", "-o", help="Write the JSON result (identify's) here, at the end and on Ctrl-C or SIGTERM."
        ),
    ] = None,
    force: Annotated[bool, typer.Option("--force", help="Overwrite an existing output file.")] = False,
    output_format: Annotated[
        OutputFormat,
        typer.Option(
            "--format", help="table (a live table), json (a JSON line per refresh), or auto (table on a terminal)."
        ),
    ] = OutputFormat.auto,
    rotor_inertia: RotorInertiaOpt = None,
    *,
    log_options: LogOptions,
    observer: ObserverOptions,
) -> None:
    """Identify the robot while it drives: follow SOURCE as it is written, refresh the estimate ± std every --every
    seconds, and when it ends (--idle, --until, --until-std, the recording's end, Ctrl-C) give identify's result on
    the same messages."""
    check_outputs((output,), force, (source,))  # before anything is imported or read; the run may take hours
    from wmrid.api.live import live as run_live
    from wmrid.reporting.live_view import json_line
    from wmrid.reporting.render import print_identification
    from wmrid.runtime import interrupts
    from wmrid.runtime.atomic import write_json

    run = run_live(
        source, robot, options=log_options, every=every, idle=idle, until=until, until_std=until_std,
        params=[p.strip() for p in params.split(",") if p.strip()] if params else None,
        observer=observer, rotor_inertia=rotor_inertia, reconnect=reconnect, monitor=monitor,
    )  # fmt: skip
    fmt = "json" if on_stdout(output) else output_format.value
    if fmt == "auto":
        fmt = "table" if sys.stdout.isatty() else "json"
    final = None
    try:
        final = _follow(run, fmt)
    except KeyboardInterrupt:
        received = interrupts.received
        final = run.finish(stopped_by="interrupted" if received in (None, 2) else f"signal {received}")
    finally:
        if final is None:
            run.close()
    result = final.result
    document = result.to_dict(history=True)
    if output is not None:
        write_json(str(output), document, force=True)  # checked before the run; the run may take hours
    line = (
        f"wmrid live: {final.reason}; {final.samples:,} samples received; the result is identify on {final.read_from}"
    )
    if final.failure is not None:
        line = (
            f"wmrid live: {final.failure}; the result so far ({final.samples:,} samples) is identify on "
            f"{final.read_from}"
        )
    sys.stderr.write(line + (f", written to {output}" if output is not None else "") + "\n")
    if fmt == "json":
        if not on_stdout(output):
            sys.stdout.write(json_line(final.to_dict()) + "\n")
            sys.stdout.flush()
        warning_summary(document["warnings"])
    else:
        print_identification(result, console())
    if final.stopped:
        raise typer.Exit(code=interrupts.exit_code())
    if final.failure is not None:
        raise typer.Exit(code=1)


def _follow(run, fmt: str):
    """Show the updates of ``run`` as they come; the final :class:`wmrid.api.live.LiveResult`."""
    from wmrid.api.live import LiveChange, LiveResult
    from wmrid.reporting.live_view import json_line

    if fmt == "json":
        for item in run:
            if isinstance(item, LiveResult):
                return item
            if isinstance(item, LiveChange):
                sys.stdout.write(json_line(item.to_dict()) + "\n")
                sys.stdout.flush()
                continue
            _events(item.events)
            sys.stdout.write(json_line(item.to_dict()) + "\n")
            sys.stdout.flush()
        return run.finish()
    from rich.live import Live

    from wmrid.reporting.live_view import change_line, live_table

    previous = None
    with Live(console=console(), auto_refresh=False, transient=True) as view:
        for item in run:
            if isinstance(item, LiveResult):
                return item
            if isinstance(item, LiveChange):
                view.console.print(change_line(item))
                continue
            _events(item.events)
            view.update(live_table(item, previous), refresh=True)
            previous = item
    return run.finish()


def _events(events) -> None:
    """What happened to the source (a connection lost or regained, a server's warning): a line each on stderr."""
    for event in events:
        sys.stderr.write(f"wmrid live: {event}\n")
    if events:
        sys.stderr.flush()
