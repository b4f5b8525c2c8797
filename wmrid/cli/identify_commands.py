"""``wmrid identify``, ``inspect``, ``report`` and ``compare``: each a translation of its flags into one library call
(:mod:`wmrid.api`) and a rendering of the result.

Imports inside functions: start-up time (``wmrid --help`` and each command load only what that command runs).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from wmrid.cli.app import app, invocation
from wmrid.cli.groups import FIT_FLAGS, LOG_FLAGS, OBSERVER_FLAGS, takes
from wmrid.cli.help import Command
from wmrid.cli.helpers import (
    activity,
    check_estimates_output,
    check_outputs,
    check_rotor,
    deprecated_option,
    on_stdout,
    progress,
    stderr_console,
    warning_summary,
    write_estimates,
)
from wmrid.cli.options import (
    GivenOpt,
    MethodChoice,
    MethodOpt,
    OutputFormat,
    RotorInertiaOpt,
    ValidateOpt,
    VerboseOpt,
)
from wmrid.core.errors import UsageError
from wmrid.reporting.terminal import console

if TYPE_CHECKING:
    from wmrid.api.inputs import LogOptions
    from wmrid.estimators.options import MethodOptions, ObserverOptions


LOG_HELP = (
    "Log: .csv (also gzip/bz2/xz/zstd), .parquet, .mcap, ROS 1 .bag, ROS 2 .db3, a rosbag2 folder, several bag "
    "files of one recording, or - for standard input."
)


def one_or_many(paths: list[str]) -> str | list[str]:
    """The LOG arguments: one path, or the files of one recording."""
    return paths[0] if len(paths) == 1 else paths


@app.command(
    cls=Command,
    name="identify",
    epilog="Examples:\n\n"
    "wmrid identify run.mcap --robot paper\n\n"
    "wmrid identify run.bag --velocity-topic /wheel_state --effort-topic /wheel_cmd --format json | jq .parameters\n\n"
    "wmrid identify log.csv.gz --columns t=time,eta_r=vr,eta_l=vl,tau_r=ur,tau_l=ul -o result.json",
)
@takes(LOG_FLAGS, OBSERVER_FLAGS, FIT_FLAGS)
def identify_command(
    log: Annotated[list[str], typer.Argument(metavar="LOG", help=LOG_HELP)],
    robot: Annotated[
        str | None,
        typer.Option(
            help="Robot: built-in name ('paper'), TOML file, or URDF (with --gear-ratio); starts the estimate."
        ),
    ] = None,
    output_format: Annotated[
        OutputFormat, typer.Option("--format", help="table, json, or auto (table on a terminal, json in a pipe).")
    ] = OutputFormat.auto,
    output: Annotated[Path | None, typer.Option("--output", "-o", help="Write the JSON result to this file.")] = None,
    mcap_out: Annotated[
        Path | None,
        typer.Option(
            "--mcap-out",
            help="Write the estimates over time and the prediction errors as an MCAP (JSON topic), to plot in "
            "Foxglove beside the log.",
        ),
    ] = None,
    out: Annotated[Path | None, typer.Option("--out", hidden=True, help="Old spelling of --mcap-out.")] = None,
    no_history: Annotated[
        bool,
        typer.Option(
            "--no-history",
            help="Leave the estimates over time (most of its size) out of the JSON result; --history, the default, "
            "keeps them.",
        ),
    ] = False,
    history: Annotated[bool, typer.Option("--history", hidden=True, help="Keep the history (the default).")] = False,
    force: Annotated[bool, typer.Option("--force", help="Overwrite an existing output file.")] = False,
    verbose: VerboseOpt = False,
    rotor_inertia: RotorInertiaOpt = None,
    method: MethodOpt = MethodChoice.auto,
    validate: ValidateOpt = None,
    given: GivenOpt = None,
    *,
    log_options: LogOptions,
    observer: ObserverOptions,
    fit: MethodOptions,
) -> None:
    """Identify the base parameters [m11 m12 m22 Vc Fv1 Fv2 Fd1 Fd2] of the robot that recorded LOG."""
    if out is not None:
        deprecated_option("--out", "--mcap-out")
        mcap_out = mcap_out or out
    check_estimates_output(mcap_out)  # before anything is imported or read: a refusal is instant
    check_outputs((output, mcap_out), force, (*log, validate))
    from wmrid.api.identification import check_validation, identify as run_identify, robot_for, validate as run_validate
    from wmrid.reporting.render import print_identification, to_json
    from wmrid.runtime.atomic import output_group, write_json

    logs = one_or_many(log)
    check_validation(logs, validate, observer, (method.value,), "LOG")
    robot_obj = robot_for(robot, log_options, check_rotor(rotor_inertia))
    progress_cb, finish = progress("identify")
    try:
        result = run_identify(
            logs, robot_obj, method=method.value, options=log_options, observer=observer, fit=fit, given=given,
            progress=progress_cb,
        )  # fmt: skip
        if validate is not None:
            result = run_validate(result, validate, log_options, robot=robot_obj)
    finally:
        finish()
    payload = result.to_dict(history=history or not no_history)
    with output_group():  # the result and the estimates appear together or not at all (a signal between: neither)
        if output is not None:
            write_json(str(output), payload, force=force)
        if mcap_out is not None:
            write_estimates(result, mcap_out, force)
    fmt = "json" if on_stdout(output) else output_format.value
    if fmt == "auto":
        fmt = "table" if sys.stdout.isatty() else "json"
    if fmt == "json":
        if not on_stdout(output):  # else the result went to standard output already
            sys.stdout.write(to_json(payload) + "\n")
        warning_summary(payload["warnings"])
    else:
        print_identification(result, console(), verbose=verbose)


@app.command(
    cls=Command,
    name="inspect",
    epilog="Examples:\n\nwmrid inspect run.mcap\n\nwmrid inspect rosbag2_folder/ --format json",
)
def inspect_command(
    log: Annotated[list[str], typer.Argument(metavar="LOG", help=LOG_HELP)],
    output_format: Annotated[
        OutputFormat, typer.Option("--format", help="table, json, or auto (table on a terminal, json in a pipe).")
    ] = OutputFormat.auto,
) -> None:
    """What LOG holds: topics, types, counts, rates, time range and JointState joints (MCAP), or columns."""
    from wmrid.io.inspect import inspect_log
    from wmrid.reporting.render import print_inspection, to_json

    info = inspect_log(one_or_many(log))
    fmt = output_format.value
    if fmt == "auto":
        fmt = "table" if sys.stdout.isatty() else "json"
    if fmt == "json":
        sys.stdout.write(to_json(info.to_dict()) + "\n")
    else:
        print_inspection(info, console())


@app.command(
    cls=Command,
    name="report",
    epilog="Examples:\n\n"
    "wmrid report run.mcap --robot paper -o report.html\n\n"
    "wmrid identify run.mcap -o result.json; wmrid report result.json -o report.md",
)
@takes(LOG_FLAGS, OBSERVER_FLAGS, FIT_FLAGS)
def report_command(
    input_: Annotated[
        str,
        typer.Argument(
            metavar="INPUT", help="A log (identified on the fly) or an `identify --format json` result; - for stdin."
        ),
    ],
    output: Annotated[
        Path | None, typer.Option("--output", "-o", help="Write the report: .html (self-contained), .md or .json.")
    ] = None,
    truth: Annotated[
        Path | None, typer.Option(help='Ground truth JSON {"parameters": {"m11": ...}} (the simulator\'s sidecar).')
    ] = None,
    residuals: Annotated[
        Path | None, typer.Option(help="Export the prediction errors over time (t, e_r, e_l) as .csv or .parquet.")
    ] = None,
    robot: Annotated[str | None, typer.Option(help="Robot (name, TOML or URDF), as for identify.")] = None,
    given: GivenOpt = None,
    force: Annotated[bool, typer.Option("--force", help="Overwrite existing output files.")] = False,
    rotor_inertia: RotorInertiaOpt = None,
    method: MethodOpt = MethodChoice.auto,
    validate: ValidateOpt = None,
    *,
    log_options: LogOptions,
    observer: ObserverOptions,
    fit: MethodOptions,
) -> None:
    """Tables (paper Tables 2 and 3), comparison with nominal/CAD/truth, diagnostics and figures for INPUT; for a
    plan (wmrid plan -o plan.json): its path, signals against their limits and predicted precision."""
    check_outputs((output,), force, (input_, truth, validate))  # before anything is imported or read
    from wmrid.api.identification import load_truth
    from wmrid.api.planning import plan_document, write_plan_report
    from wmrid.api.reporting import REPORT_SUFFIXES, Identification, report as build, residual_frame, write_report

    planned = plan_document(input_)
    if planned is not None:
        if output is None:
            from wmrid.reporting.plan_view import print_plan

            print_plan(planned, console())
        else:
            write_plan_report(planned, output, force=force)
            stderr_console().print(f"wrote {output}")
        return

    suffix = output.suffix.lower() if output is not None else None
    if suffix not in (None, *REPORT_SUFFIXES):
        raise UsageError(f"-o {output}: the report format comes from the suffix: .html, .md or .json")
    check_outputs((residuals,), force)  # (not a plan's: it has none)
    truth_params = load_truth(truth)
    if input_ == "-" and validate == "-":
        raise UsageError("INPUT and --validate cannot both be standard input; give one of them as a file")
    how = Identification(method.value, observer, fit, validate, given)
    with activity("wmrid report") as stage:
        drawn = suffix in (".html", ".htm", ".md")  # the outputs that show figures
        stage("identifying" + (" and drawing the figures" if drawn else ""))
        rep = build(
            input_, truth=truth_params, figures=drawn, rotor_inertia=rotor_inertia, options=log_options, robot=robot,
            identification=how, command=invocation(),
        )  # fmt: skip
        from wmrid.runtime.atomic import output_group

        with output_group():  # the residuals and the report appear together or not at all
            if residuals is not None:
                from wmrid.io.logs import write_log

                write_log(residual_frame(rep), str(residuals), force=force)
            if output is not None:
                stage(f"writing {output}")
                write_report(rep, output, force=force)
    if output is None:
        from wmrid.reporting.render import print_report

        print_report(rep, console())
    if output is not None:
        stderr_console().print(f"wrote {output}")


@app.command(
    cls=Command,
    name="compare",
    epilog="Examples:\n\n"
    "wmrid compare run.mcap --robot paper\n\n"
    "wmrid compare sim.csv --truth sim.csv.truth.json --methods observer,idim,oe --validate other.csv",
)
@takes(LOG_FLAGS, OBSERVER_FLAGS, FIT_FLAGS)
def compare_command(
    log: Annotated[list[str], typer.Argument(metavar="LOG", help=LOG_HELP)],
    robot: Annotated[
        str | None, typer.Option(help="Robot (name, TOML or URDF): starts the observer and gives nominal/CAD values.")
    ] = None,
    truth: Annotated[
        Path | None, typer.Option(help='Ground truth JSON {"parameters": {"m11": ...}} (the simulator\'s sidecar).')
    ] = None,
    validate: ValidateOpt = None,
    methods: Annotated[
        str, typer.Option(help="Comma-separated methods to run, of observer, idim, iv, rls, oe.")
    ] = "observer,idim,rls,oe",
    output_format: Annotated[
        OutputFormat, typer.Option("--format", help="table, json, or auto (table on a terminal, json in a pipe).")
    ] = OutputFormat.auto,
    output: Annotated[
        Path | None, typer.Option("--output", "-o", help="Write the JSON comparison to this file.")
    ] = None,
    force: Annotated[bool, typer.Option("--force", help="Overwrite an existing output file.")] = False,
    rotor_inertia: RotorInertiaOpt = None,
    *,
    log_options: LogOptions,
    observer: ObserverOptions,
    fit: MethodOptions,
) -> None:
    """Run every identification method on LOG: estimates, standard errors, errors against --truth, fit on
    --validate OTHER, run time.  Every method identifies the same friction model (--friction)."""
    check_outputs((output,), force, (*log, validate, truth))  # before anything is imported or read
    from wmrid.api.identification import compare as run_compare, robot_for
    from wmrid.reporting.render import print_comparison, to_json
    from wmrid.runtime.atomic import write_json

    robot_obj = robot_for(robot, log_options, check_rotor(rotor_inertia))
    with activity("wmrid compare") as stage:
        comparison = run_compare(
            one_or_many(log), robot_obj, methods=methods.split(","), options=log_options, observer=observer, fit=fit,
            validate=validate, truth=truth, stage=stage,
        )  # fmt: skip
    data = comparison.to_dict()
    if output is not None:
        write_json(str(output), data, force=force)
    fmt = "json" if on_stdout(output) else output_format.value
    if fmt == "auto":
        fmt = "table" if sys.stdout.isatty() else "json"
    if fmt == "json":
        if not on_stdout(output):  # else the result went to standard output already
            sys.stdout.write(to_json(data) + "\n")
        warning_summary([f"{name}: {w}" for name, m in comparison.methods.items() for w in m.warnings],
                        "each method's \"warnings\" in the JSON")  # fmt: skip
    else:
        print_comparison(comparison, console())
