"""The ``wmrid`` command line: a thin Typer layer over typed functions.

Heavy modules (numpy, pandas, numba, rich) are imported inside the commands so that ``wmrid --help``
answers at once.  :func:`main` is the one place that maps errors to exit codes and messages.
"""

from __future__ import annotations

import os
import sys
from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from wmrid import __version__
from wmrid.errors import ExitStatus, UsageError, WmridError

app = typer.Typer(
    name="wmrid",
    help="Identify the dynamic parameters of differential-drive wheeled mobile robots from their logs "
    "(Hoang & Kang 2015).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)


class OutputFormat(str, Enum):
    auto = "auto"
    table = "table"
    json = "json"


class FormChoice(str, Enum):
    auto = "auto"
    paper = "paper"
    general = "general"


class TimeUnit(str, Enum):
    auto = "auto"
    s = "s"
    ms = "ms"
    us = "us"
    ns = "ns"


class TorqueHold(str, Enum):
    zoh = "zoh"
    foh = "foh"


class Trajectory(str, Enum):
    sinusoid = "sinusoid"
    reversing = "reversing"


def _version(value: bool) -> None:
    if value:
        typer.echo(f"wmrid {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    debug: Annotated[bool, typer.Option("--debug", help="Show the full traceback of any error.")] = False,
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version and exit.")
    ] = False,
) -> None:
    """wmrid: observer-based dynamic parameter identification for wheeled mobile robots."""


def _stderr_console():
    from rich.console import Console

    return Console(stderr=True)


@app.command()
def identify(
    log: Annotated[str, typer.Argument(metavar="LOG", help="Log file (.csv, .parquet) or - for standard input.")],
    robot: Annotated[
        str | None,
        typer.Option(help="Robot TOML file or built-in name ('paper'): nominal values start the estimate."),
    ] = None,
    columns: Annotated[
        str | None, typer.Option(help="Column mapping, e.g. t=time,eta_r=vel_right,tau_l=effort_left.")
    ] = None,
    time_unit: Annotated[
        TimeUnit, typer.Option(help="Unit of the time column (auto: float s, integer ns).")
    ] = TimeUnit.auto,
    form: Annotated[
        FormChoice, typer.Option(help="Regressor: paper (7 columns, wheels keep one sign), general (8), auto.")
    ] = FormChoice.auto,
    k: Annotated[
        float, typer.Option("--k", help="Observer/filter gain k of Eqs. 26-30, 1/s (paper: 1; see README).")
    ] = 10.0,
    alpha: Annotated[
        float, typer.Option(help="Initial Gamma = alpha I (Eq. 33): weight of the start value (paper: 5000).")
    ] = 1e-10,
    box_width: Annotated[
        float,
        typer.Option(help="Half-width of the parameter box around the nominal values, in units of max(|theta|, m_ii)."),
    ] = 10.0,
    torque_hold: Annotated[
        TorqueHold,
        typer.Option(help="Torque between samples: zoh (held, as a digital controller applies it) or foh (linear)."),
    ] = TorqueHold.zoh,
    output_format: Annotated[
        OutputFormat, typer.Option("--format", help="table, json, or auto (table on a terminal, json in a pipe).")
    ] = OutputFormat.auto,
    output: Annotated[Path | None, typer.Option("--output", "-o", help="Write the JSON result to this file.")] = None,
    force: Annotated[bool, typer.Option(help="Overwrite an existing output file.")] = False,
) -> None:
    """Identify the base parameters [m11 m12 m22 Vc Fv1 Fv2 Fd1 Fd2] of the robot that recorded LOG."""
    from wmrid.atomic import write_json
    from wmrid.identify import identify as run_identify
    from wmrid.logio import parse_column_mapping, read_log
    from wmrid.render import print_identification, to_json
    from wmrid.robot import load_robot

    robot_obj = load_robot(robot) if robot is not None else None
    mapping = parse_column_mapping(columns) if columns else None
    wheel_log = read_log(log, columns=mapping, time_unit=time_unit.value)
    progress_cb, finish = _progress(len(wheel_log), "identify")
    try:
        result = run_identify(
            wheel_log,
            robot_obj,
            form=form.value,
            k=k,
            alpha=alpha,
            box_width=box_width,
            torque_hold=torque_hold.value,
            progress=progress_cb,
        )
    finally:
        finish()
    payload = result.to_dict()
    if output is not None:
        write_json(str(output), payload, force=force)
    fmt = output_format.value
    if fmt == "auto":
        fmt = "table" if sys.stdout.isatty() else "json"
    if fmt == "json":
        sys.stdout.write(to_json(payload) + "\n")
    else:
        from rich.console import Console

        print_identification(result, Console())


def _progress(total: int, label: str):
    """A rich progress bar on stderr for long logs when stderr is a terminal; else no-ops."""
    if total < 1_000_000 or not sys.stderr.isatty():
        return None, lambda: None
    from rich.progress import Progress

    bar = Progress(console=_stderr_console(), transient=True)
    task = bar.add_task(label, total=total)
    bar.start()
    return (lambda done: bar.update(task, completed=done)), bar.stop


@app.command()
def simulate(
    output: Annotated[
        str, typer.Option("--output", "-o", help="Log to write: .csv or .parquet (- for CSV on stdout).")
    ],
    robot: Annotated[str, typer.Option(help="Robot TOML file or built-in name; its CAD set is the truth.")] = "paper",
    trajectory: Annotated[Trajectory, typer.Option(help="Reference trajectory.")] = Trajectory.sinusoid,
    duration: Annotated[float, typer.Option(help="Duration, s.")] = 40.0,
    rate: Annotated[float, typer.Option(help="Log rate, Hz (control runs at 1 kHz).")] = 1000.0,
    seed: Annotated[int, typer.Option(help="Seed of every random number.")] = 0,
    payload: Annotated[
        str | None, typer.Option(help="Rigid payload MASS[@X,Y] (kg, m in the platform frame), e.g. 25@0.1,-0.05.")
    ] = None,
    payload_inertia: Annotated[
        float, typer.Option(help="Payload yaw inertia about its own centre of mass, kg m^2.")
    ] = 0.0,
    eta_noise: Annotated[float, typer.Option(help="Std of white noise on logged wheel speeds, rad/s.")] = 0.0,
    tau_noise: Annotated[float, typer.Option(help="Std of white noise on logged torques, N m.")] = 0.0,
    caster: Annotated[float, typer.Option(help="Std of the coloured caster disturbance torque, N m.")] = 0.0,
    caster_time: Annotated[float, typer.Option(help="Correlation time of the caster disturbance, s.")] = 0.3,
    encoder_cpr: Annotated[int, typer.Option(help="Encoder counts per wheel revolution (0: no quantisation).")] = 0,
    force: Annotated[bool, typer.Option(help="Overwrite existing output files.")] = False,
) -> None:
    """Simulate the paper's virtual prototype and write a log plus its ground truth (<log>.truth.json)."""
    from wmrid.atomic import to_json_text, write_json
    from wmrid.logio import write_log
    from wmrid.robot import Payload, load_robot
    from wmrid.simulate import NoiseSettings
    from wmrid.simulate import simulate as run_simulate

    robot_obj = load_robot(robot)
    truth_params = robot_obj.reference
    load = None
    if payload is not None:
        load = Payload.parse(payload, inertia=payload_inertia)
        truth_params = truth_params.with_payload(load)
    elif payload_inertia:
        raise UsageError("--payload-inertia needs --payload MASS[@X,Y]")
    noise = NoiseSettings(
        eta_std=eta_noise, tau_std=tau_noise, caster_std=caster, caster_time=caster_time, encoder_cpr=encoder_cpr
    )
    sim = run_simulate(
        truth_params,
        robot_obj.nominal,
        trajectory=trajectory.value,
        duration=duration,
        rate=rate,
        noise=noise,
        seed=seed,
    )
    truth = sim.truth()
    truth["robot"] = robot_obj.name
    if load is not None:
        truth["payload"] = {"mass": load.mass, "x": load.x, "y": load.y, "inertia": load.inertia}
    truth_path = None if output == "-" else output + ".truth.json"
    if truth_path is not None and not force and os.path.exists(truth_path):
        raise UsageError(f"{truth_path} exists; use --force to overwrite it")
    write_log(sim.to_frame(), output, force=force, metadata={"wmrid_truth": to_json_text(truth)})
    if truth_path is not None:
        write_json(truth_path, truth, force=force)
        _stderr_console().print(f"wrote {output} ({len(sim.t)} samples) and {truth_path}")


def main(argv: list[str] | None = None) -> None:
    """Entry point: run the app and map every outcome to one exit code and at most one stderr line."""
    args = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in args
    try:
        rv = app(args=args, prog_name="wmrid", standalone_mode=False)
        code = rv if isinstance(rv, int) else ExitStatus.OK
    except KeyboardInterrupt:
        sys.stderr.write("wmrid: interrupted\n")
        code = ExitStatus.INTERRUPTED
    except WmridError as exc:
        if debug:
            raise
        sys.stderr.write(f"wmrid: error: {_one_line(str(exc))}\n")
        code = exc.exit_status
    except BrokenPipeError:
        code = ExitStatus.OK
    except Exception as exc:
        if hasattr(exc, "show") and hasattr(exc, "exit_code"):  # a Click/Typer usage error: its own message
            exc.show()
            code = ExitStatus.USAGE
        elif type(exc).__name__ == "Abort":
            code = ExitStatus.INTERRUPTED
        elif debug:
            raise
        else:  # the last resort: never a traceback without --debug
            sys.stderr.write(
                f"wmrid: internal error: {type(exc).__name__}: {_one_line(str(exc))} "
                "(run with --debug for the traceback)\n"
            )
            code = ExitStatus.NO_RESULT
    sys.exit(int(code))


def _one_line(text: str) -> str:
    return " ".join(text.split())
