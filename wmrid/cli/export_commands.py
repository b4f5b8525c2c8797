"""``wmrid export``: a translation of its flags into one library call (:func:`wmrid.api.exporting.export`).

Imports inside functions: start-up time (``wmrid --help`` and each command load only what that command runs).
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, Annotated

import typer

from wmrid.cli.app import app
from wmrid.cli.groups import LOG_FLAGS, takes
from wmrid.cli.help import Command
from wmrid.cli.helpers import activity
from wmrid.cli.options import (
    CHECK_LOG_PANEL,
    OutputFormat,
    RotorInertiaOpt,
)
from wmrid.reporting.terminal import console

if TYPE_CHECKING:
    from wmrid.api.inputs import LogOptions


@app.command(
    cls=Command,
    name="export",
    epilog="Examples:\n\n"
    "wmrid export run.json --robot robot.toml -o robot.xml --check run.mcap\n\n"
    "wmrid export run.json --robot robot.urdf --gear-ratio 100 -o identified.urdf\n\n"
    "wmrid export run.json --robot amr -o model.yaml\n\n"
    "wmrid export run.json --robot amr -o feedforward.py",
)
@takes(LOG_FLAGS.adapted(panel=CHECK_LOG_PANEL))
def export_command(
    result: Annotated[
        str, typer.Argument(metavar="RESULT", help="A saved result (wmrid identify --format json -o run.json).")
    ],
    output: Annotated[
        str,
        typer.Option(
            "--output",
            "-o",
            help="Write the model; by suffix: .xml (MJCF for MuJoCo), .urdf (your URDF with the identified inertial "
            "and wheel dynamics, or a minimal one for a TOML robot), .yaml (the reduced model for a controller), .py "
            "(a dependency-free wheel_torques(eta, eta_dot)), .toml (a wmrid robot file of the identified robot, for "
            "wmrid simulate).",
        ),
    ],
    robot: Annotated[
        str,
        typer.Option(
            help="The robot file the result was identified with (TOML, URDF with --gear-ratio, or a built-in name); "
            "its geometry and wheel and rotor masses give what the log does not."
        ),
    ],
    rotor_inertia: RotorInertiaOpt = None,
    check: Annotated[
        str | None,
        typer.Option(
            help="A log whose torques drive the exported multibody model; its fit % is reported. Give it the same "
            "log-input flags the result was identified with."
        ),
    ] = None,
    window: Annotated[
        float, typer.Option(help="With --check: the windows the models restart over from the logged speeds, s, > 0.")
    ] = 2.0,
    output_format: Annotated[
        OutputFormat, typer.Option("--format", help="table, json, or auto (table on a terminal, json in a pipe).")
    ] = OutputFormat.auto,
    force: Annotated[bool, typer.Option("--force", help="Overwrite an existing output file.")] = False,
    *,
    log_options: LogOptions,
) -> None:
    """Write an identified robot as a model a simulator or a controller loads, with every value's std."""
    from wmrid.api.exporting import check_export_output, export

    check_export_output(output)
    with activity("export"):
        done = export(result, robot, output, check=check, window=window, gear_ratio=log_options.gear_ratio,
                      rotor_inertia=rotor_inertia, wheel_radius=log_options.wheel_radius, options=log_options,
                      force=force)  # fmt: skip
    from wmrid.reporting.export_view import print_export  # after the work: a refusal imports no rendering
    from wmrid.reporting.render import to_json

    fmt = output_format.value
    if fmt == "auto":
        fmt = "table" if sys.stdout.isatty() else "json"
    if fmt == "json":
        sys.stdout.write(to_json(done.to_dict()) + "\n")
    else:
        print_export(done, console())
