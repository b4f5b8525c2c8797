"""``wmrid plan``: a translation of its flags into one library call (:func:`wmrid.api.planning.plan`).

Imports inside functions: start-up time (``wmrid --help`` and each command load only what that command runs).
"""

from __future__ import annotations

import sys
from typing import Annotated

import typer

from wmrid.cli.app import app
from wmrid.cli.help import Command
from wmrid.cli.helpers import activity, check_outputs, on_stdout, warning_summary
from wmrid.cli.options import Criterion, OutputFormat, PlanFriction
from wmrid.reporting.terminal import console


@app.command(
    cls=Command,
    name="plan",
    epilog="Examples:\n\n"
    "wmrid plan --robot robot.toml --max-torque 20 -o plan.csv -o plan.json\n\n"
    "wmrid plan --robot amr --area 3x3 --noise-from old_run.mcap -o plan.mcap\n\n"
    "wmrid plan --robot robot.toml --given first_run.json --duration 30 -o next.csv\n\n"
    "wmrid plan --robot robot.toml --duration auto --target-std 2 -o plan.csv",
)
def plan_command(
    robot: Annotated[
        str, typer.Option(help="Robot TOML file or built-in name; its nominal set is planned on.")
    ] = "paper",
    output: Annotated[
        list[str] | None,
        typer.Option(
            "--output",
            "-o",
            help="Write the plan; by suffix: .csv or .parquet (t, v, omega, eta_r, eta_l, x, y, phi), .mcap (ROS 2 "
            "geometry_msgs/Twist for ros2 bag play), .json (the prediction). Repeat for several.",
        ),
    ] = None,
    duration: Annotated[str, typer.Option(help="Length of the drive, s, or auto (with --target-std).")] = "60",
    target_std: Annotated[
        float | None, typer.Option(help="With --duration auto: the largest relative std wanted, percent, > 0 (e.g. 2).")
    ] = None,
    rate: Annotated[float, typer.Option(help="Rate of the written reference, Hz, > 0.")] = 50.0,
    seed: Annotated[int, typer.Option(help="Seed of the search's random starts, >= 0.")] = 0,
    max_wheel_speed: Annotated[float | None, typer.Option(help="Wheel speed limit, rad/s, > 0.")] = None,
    max_wheel_accel: Annotated[float | None, typer.Option(help="Wheel acceleration limit, rad/s^2, > 0.")] = None,
    max_torque: Annotated[
        float | None, typer.Option(help="Torque limit per wheel, N m, > 0 (torques from the nominal model).")
    ] = None,
    max_speed: Annotated[float | None, typer.Option(help="Forward speed limit, m/s, > 0.")] = None,
    max_turn_rate: Annotated[float | None, typer.Option(help="Turn rate limit, rad/s, > 0.")] = None,
    area: Annotated[
        str | None,
        typer.Option(help="Floor area WxH, m, centred on the start (the robot at rest facing +x); default 4x4."),
    ] = None,
    margin: Annotated[float, typer.Option(help="Share of each limit kept free, in [0, 0.9).")] = 0.15,
    eta_noise: Annotated[
        float | None, typer.Option(help="White noise on each wheel speed, rad/s per sample, >= 0.")
    ] = None,
    tau_noise: Annotated[float | None, typer.Option(help="White noise on each effort, N m per sample, >= 0.")] = None,
    log_rate: Annotated[
        float | None, typer.Option(help="Rate of the log to be recorded, Hz, > 0 (default 100, or --noise-from's).")
    ] = None,
    noise_from: Annotated[
        str | None, typer.Option(help="Measure the noise (and log rate) from an earlier log of this robot.")
    ] = None,
    criterion: Annotated[
        Criterion, typer.Option(help="worst (largest relative std), d (D-optimal) or a (A-optimal).")
    ] = Criterion.worst,
    friction: Annotated[
        PlanFriction,
        typer.Option(
            help="The friction model identify will fit, which the prediction is for. auto: the casters' drag, "
            "following their load, when the robot file lists [[caster]] tables; else the wheels' alone."
        ),
    ] = PlanFriction.auto,
    given: Annotated[
        list[str] | None,
        typer.Option(help="A saved result (identify --format json) whose information the plan adds. Repeatable."),
    ] = None,
    topic: Annotated[str, typer.Option(help="Topic of the .mcap reference.")] = "/cmd_vel",
    stamped: Annotated[bool, typer.Option("--stamped", help="Write TwistStamped instead of Twist.")] = False,
    output_format: Annotated[
        OutputFormat, typer.Option("--format", help="table, json, or auto (table on a terminal, json in a pipe).")
    ] = OutputFormat.auto,
    force: Annotated[bool, typer.Option("--force", help="Overwrite existing output files.")] = False,
) -> None:
    """Design the drive that identifies ROBOT best within its limits, and predict how precise the result will be."""
    outputs = list(output or [])
    files = [p for p in outputs if not on_stdout(p)]
    check_outputs(files, force, (noise_from, *(given or ())))  # before anything is imported or read
    from wmrid.api.planning import check_plan_output, plan as make, write_plan

    for path in files:
        check_plan_output(path)
    from wmrid.reporting.plan_view import print_plan
    from wmrid.reporting.render import to_json
    from wmrid.runtime.atomic import output_group

    with activity("plan") as stage:
        result = make(
            robot, duration=duration, target_std=target_std, rate=rate, seed=seed, max_wheel_speed=max_wheel_speed,
            max_wheel_accel=max_wheel_accel, max_torque=max_torque, max_speed=max_speed, max_turn_rate=max_turn_rate,
            area=area, margin=margin, eta_noise=eta_noise, tau_noise=tau_noise, log_rate=log_rate,
            noise_from=noise_from, criterion=criterion.value, friction=friction.value, given=given, progress=stage,
        )  # fmt: skip
    with output_group():
        for path in outputs:
            if not on_stdout(path):
                write_plan(result, path, topic=topic, stamped=stamped, force=force)
    fmt = output_format.value
    if fmt == "auto":
        fmt = "table" if sys.stdout.isatty() else "json"
    if fmt == "json":
        sys.stdout.write(to_json(result.to_dict()) + "\n")
        warning_summary(list(result.warnings))
    else:
        print_plan(result, console(), [p for p in outputs if not on_stdout(p)])
