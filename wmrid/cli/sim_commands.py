"""``wmrid simulate`` and ``monitor``: each a translation of its flags into one library call (:mod:`wmrid.api`).

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
from wmrid.cli.helpers import activity, check_outputs, check_rotor, on_stdout, stderr_console, warning_summary
from wmrid.cli.options import (
    MULTIBODY_PANEL,
    NOISE_PANEL,
    CalibrationOpt,
    DropAtOpt,
    Engine,
    FalseAlarmRateOpt,
    FaultAtOpt,
    FrictionFaultOpt,
    LoadAtOpt,
    MonitorModelOpt,
    OutputFormat,
    RotorInertiaOpt,
    Trajectory,
)
from wmrid.reporting.terminal import console

if TYPE_CHECKING:
    from wmrid.api.inputs import LogOptions
    from wmrid.estimators.options import ObserverOptions


@app.command(
    cls=Command,
    name="simulate",
    epilog="Examples:\n\n"
    "wmrid simulate -o sim.csv --duration 20 --eta-noise 0.01\n\n"
    "wmrid simulate -o loaded.mcap --payload 25@0.1,-0.05 --load-at 30\n\n"
    "wmrid simulate -o drive.csv --reference plan.csv",
)
def simulate_command(
    output: Annotated[
        str, typer.Option("--output", "-o", help="Log to write: .csv, .parquet or .mcap (- for CSV on stdout).")
    ],
    robot: Annotated[str, typer.Option(help="Robot TOML file or built-in name; its CAD set is the truth.")] = "paper",
    trajectory: Annotated[
        Trajectory | None, typer.Option(help="Built-in reference trajectory; default sinusoid.", show_default=False)
    ] = None,
    duration: Annotated[
        float | None,
        typer.Option(help="Duration, s, > 0; default 40, or the whole --reference (at most that).", show_default=False),
    ] = None,
    rate: Annotated[
        float, typer.Option(help="Log rate, Hz, > 0, a whole number of 1 ms control periods per sample.")
    ] = 1000.0,
    seed: Annotated[int, typer.Option(help="Seed of every random number, >= 0.")] = 0,
    payload: Annotated[
        str | None,
        typer.Option(
            help="Rigid payload MASS[@X,Y] (kg, m in the platform frame), e.g. 25@0.1,-0.05; carried throughout "
            "unless --load-at or --drop-at says when."
        ),
    ] = None,
    payload_inertia: Annotated[
        float, typer.Option(help="Payload yaw inertia about its own centre of mass, kg m^2, >= 0.")
    ] = 0.0,
    eta_noise: Annotated[
        float, typer.Option(help="Std of white noise on logged wheel speeds, rad/s, >= 0.", rich_help_panel=NOISE_PANEL)
    ] = 0.0,
    tau_noise: Annotated[
        float, typer.Option(help="Std of white noise on logged torques, N m, >= 0.", rich_help_panel=NOISE_PANEL)
    ] = 0.0,
    caster: Annotated[
        float,
        typer.Option(help="Std of the coloured caster disturbance torque, N m, >= 0.", rich_help_panel=NOISE_PANEL),
    ] = 0.0,
    caster_time: Annotated[
        float,
        typer.Option(help="Correlation time of the caster disturbance, s, > 0.", rich_help_panel=NOISE_PANEL),
    ] = 0.3,
    encoder_cpr: Annotated[
        int,
        typer.Option(
            help="Encoder counts per wheel revolution, >= 0 (0: no quantisation).", rich_help_panel=NOISE_PANEL
        ),
    ] = 0,
    force: Annotated[bool, typer.Option("--force", help="Overwrite existing output files.")] = False,
    gear_ratio: Annotated[float | None, typer.Option(help="URDF robots: gear ratio k_r, > 0.")] = None,
    rotor_inertia: RotorInertiaOpt = None,
    load_at: LoadAtOpt = None,
    drop_at: DropAtOpt = None,
    friction_fault: FrictionFaultOpt = None,
    fault_at: FaultAtOpt = None,
    engine: Annotated[
        Engine,
        typer.Option(
            help="reduced: the paper's reduced model (Eqs. 9-14); mujoco: a multibody prototype (rigid bodies, "
            "wheel-ground contact, casters) that knows nothing of those equations (pip install 'wmrid[physics]').",
            rich_help_panel=MULTIBODY_PANEL,
        ),
    ] = Engine.reduced,
    floor_friction: Annotated[
        float | None,
        typer.Option(
            help="mujoco: Coulomb friction of the wheels on the floor, in (0, 100] (low values let them slip); "
            "default 1.0.",
            rich_help_panel=MULTIBODY_PANEL,
        ),
    ] = None,
    caster_resistance: Annotated[
        float | None,
        typer.Option(
            help="mujoco: rolling-resistance coefficient of every caster, >= 0 (drag / normal load; 0: frictionless); "
            "default: the robot file's [[caster]] values, else 0.015 (polyurethane).",
            rich_help_panel=MULTIBODY_PANEL,
        ),
    ] = None,
    torque_limit: Annotated[
        float | None,
        typer.Option(help="mujoco: clip each wheel torque to +-this, N m, > 0.", rich_help_panel=MULTIBODY_PANEL),
    ] = None,
    reference: Annotated[
        str | None,
        typer.Option(
            help="Track this reference drive instead of --trajectory: a .csv or .parquet file with columns t (s), "
            "v (m/s), omega (rad/s), or an .mcap of geometry_msgs Twist / TwistStamped messages (e.g. from wmrid "
            "plan); it starts at the origin facing +x."
        ),
    ] = None,
    reference_topic: Annotated[
        str | None, typer.Option(help="The Twist topic of an MCAP --reference; default: its only one.")
    ] = None,
) -> None:
    """Simulate the paper's virtual prototype and write a log plus its ground truth (<log>.truth.json).

    The dynamics may change once during the run (a payload loaded or dropped, a wheel's friction grown), the
    controller keeping the nominal parameters; the truth's "parameters" are those at t = 0, its settings.change holds
    both sets and the switch time.
    """
    if output != "-":  # the log and its truth, refused before anything is imported or simulated
        check_outputs((output, output + ".truth.json"), force, (reference,))
    from wmrid.api.identification import robot_for
    from wmrid.api.inputs import LogOptions
    from wmrid.api.simulation import simulate as run_simulate, write_simulation
    from wmrid.cli.sim_flags import change_of, engine_of, payload_of, reference_of
    from wmrid.sim.scenario import NoiseSettings
    from wmrid.sim.simulate import plan_duration

    load = payload_of(payload, payload_inertia)
    drive = reference_of(None if trajectory is None else trajectory.value, reference, reference_topic)
    end = plan_duration(duration, None if drive is None or isinstance(drive, str) else drive)
    robot_obj = robot_for(robot, LogOptions(gear_ratio=gear_ratio), check_rotor(rotor_inertia))
    change = change_of(load, load_at, drop_at, friction_fault, fault_at, end, robot_obj)
    noise = NoiseSettings(
        eta_std=eta_noise, tau_std=tau_noise, caster_std=caster, caster_time=caster_time, encoder_cpr=encoder_cpr,
        seed=seed,
    )  # fmt: skip
    settings = engine_of(engine.value, floor_friction, caster_resistance, torque_limit)
    with activity("wmrid simulate") as stage:
        what = f"{duration:g} s" if duration is not None else "the reference" if reference is not None else "40 s"
        stage(f"{what} on the {engine.value} model")
        run = run_simulate(
            robot_obj, trajectory=drive, duration=duration, rate=rate, noise=noise, payload=load, change=change,
            engine=settings,
        )  # fmt: skip
        stage(f"writing {output}")
        truth_path = write_simulation(run, output, force=force)
    if truth_path is not None:
        change = run.change
        what = "" if change is None else f", {change.kind} at {run.log.settings['change']['t_switch']:g} s"
        stderr_console().print(f"wrote {output} ({len(run.log.t)} samples{what}) and {truth_path}")


#: The observer's flags as monitor reads them: the identifications after a change use them; the friction model is the
#: model's, a delay shifts the whole log before the test, and a payload is not estimated (no robot file).
MONITOR_OBSERVER_FLAGS = OBSERVER_FLAGS.adapted(
    without=("payload",),
    texts={
        "delay": "The efforts are stamped SECONDS later than the speeds (two topics, two clocks; negative: earlier): "
        "the whole log's efforts are read that much earlier before the test.  auto: the delay estimated on the "
        "calibration span (assumed unchanged) and applied when significant.  Default: as stamped (monitor runs no "
        "timing check).",
        "friction": "The friction model the identifications after a change use: the model's (auto, the default, or "
        "its name); another is refused (identify the model with it).",
    },
)


@app.command(
    cls=Command,
    name="monitor",
    epilog="Examples:\n\nwmrid identify monday.mcap -o model.json; wmrid monitor friday.mcap --model model.json",
)
@takes(LOG_FLAGS, MONITOR_OBSERVER_FLAGS)
def monitor_command(
    log: Annotated[
        str, typer.Argument(metavar="LOG", help="Log file (.csv, .parquet, .mcap) or - for standard input.")
    ],
    model: MonitorModelOpt,
    calibration: CalibrationOpt = 10.0,
    false_alarm_rate: FalseAlarmRateOpt = 0.1,
    output_format: Annotated[
        OutputFormat, typer.Option("--format", help="table, json, or auto (table on a terminal, json in a pipe).")
    ] = OutputFormat.auto,
    output: Annotated[Path | None, typer.Option("--output", "-o", help="Write the JSON result to this file.")] = None,
    force: Annotated[bool, typer.Option("--force", help="Overwrite an existing output file.")] = False,
    *,
    log_options: LogOptions,
    observer: ObserverOptions,
) -> None:
    """Replay LOG against an identified model; report when the dynamics change, and the parameters after.

    A windowed likelihood-ratio test on the model's torque residual, with a stated false-alarm rate, finds
    changes such as a payload loaded or dropped or a wheel's friction rising; after each, the robot is
    identified again and the test restarts.  JSON: {"changes": [{"t": s from the log's start,
    "parameters": {...}, ...}], "detector": {..., "threshold", "false_alarm_rate_per_hour"}, ...}.
    """
    check_outputs((output,), force, (log, model))  # before anything is imported or read
    from wmrid.api.monitoring import monitor as run_monitor
    from wmrid.reporting.monitor_view import print_monitor
    from wmrid.reporting.render import to_json
    from wmrid.runtime.atomic import write_json

    with activity("wmrid monitor"):
        result = run_monitor(
            log,
            model,
            options=log_options,
            observer=observer,
            calibration=calibration,
            false_alarm_rate=false_alarm_rate,
        )
    payload = result.to_dict()
    if output is not None:
        write_json(str(output), payload, force=force)
    fmt = "json" if on_stdout(output) else output_format.value
    if fmt == "auto":
        fmt = "table" if sys.stdout.isatty() else "json"
    if fmt == "json":
        if not on_stdout(output):  # else the result went to standard output already
            sys.stdout.write(to_json(payload) + "\n")
        warning_summary([*(f"after the change at {c.t:.3f} s: {w}" for c in result.changes for w in c.warnings),
                         *result.warnings])  # fmt: skip
    else:
        print_monitor(result, console())
