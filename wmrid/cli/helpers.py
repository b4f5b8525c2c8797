"""What the commands share beyond their options: reading a log and a robot with the flags' values, progress, where
the output goes.

Imports inside functions: start-up time (``wmrid --help`` and each command load only what that command runs).
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

from wmrid.core.errors import UsageError


def check_rotor(rotor_inertia: float | None) -> float | None:
    """``--rotor-inertia``, refused unless a finite number >= 0 kg m^2."""
    from wmrid.api.identification import check_rotor_inertia

    check_rotor_inertia(rotor_inertia)
    return rotor_inertia


def check_outputs(outputs: Iterable[Path | str | None], force: bool, inputs: Iterable[Path | str | None] = ()) -> None:
    """Refuse, before any import of the numerics and any reading, an output the command could not write at its end
    (:func:`wmrid.runtime.atomic.check_output`: an existing file without ``--force``, a missing folder, one of the
    ``inputs`` the command reads), with the message the write would give; None entries are skipped."""
    from wmrid.runtime.atomic import check_output, register_input

    for name in inputs:
        if name is not None and name != "-":  # standard input is never an output's file
            register_input(name)
    for path in outputs:
        if path is not None:
            check_output(path, force=force)


def check_estimates_output(path: Path | None) -> None:
    """``--mcap-out``: the estimates are written as MCAP (:func:`write_estimates`)."""
    if path is not None and path.suffix.lower() != ".mcap":
        raise UsageError(f"--mcap-out {path}: the estimates are written as MCAP; name the file .mcap")


def stderr_console():
    from wmrid.reporting.terminal import console

    return console(stderr=True)


def warning_summary(warnings: list[str], where: str = 'the JSON\'s "warnings"') -> None:
    """One line on stderr when a JSON result carries warnings, so that a script reading one figure from it learns
    that the log may not support it: the count and the first warning."""
    if not warnings:
        return
    first = " ".join(warnings[0].split())
    if len(first) > 160:
        first = first[:159] + "…"
    count = f"{len(warnings)} warning" + ("s" if len(warnings) > 1 else "")
    sys.stderr.write(f"wmrid: {count} (see {where}); the first: {first}\n")


def deprecated_option(old: str, new: str) -> None:
    """A note on stderr that an option's old spelling was used (it keeps working)."""
    sys.stderr.write(f"wmrid: note: {old} is now {new}; {old} still works but will go\n")


def write_estimates(result, path: Path, force: bool) -> None:
    """The recorded history of an identification as an MCAP JSON topic /wmrid/estimates: the intermediate
    estimates theta_ij, the base parameters recovered from them (their names, as ``identify`` reports them) with
    the final estimate's std (``NAME_std``, the same in every message), the prediction errors and lambda_min."""
    import numpy as np

    from wmrid.io.mcap.series_writer import write_series_mcap
    from wmrid.model.base_params import recover_history
    from wmrid.runtime.atomic import to_json_text

    check_estimates_output(path)
    hist = result.history
    series = {name: hist.theta[:, i // hist.theta.shape[2], i % hist.theta.shape[2]] for i, name in
              enumerate(result.form.theta_names())}  # fmt: skip
    base = recover_history(hist.theta, result.form)
    for j, name in enumerate(result.form.base_names):
        series[name] = base[:, j]
        std = result.parameters.get(name, (np.nan, np.nan))[1]
        series[f"{name}_std"] = np.full(len(hist.t), std if std is not None else np.nan)
    series["e_r"] = hist.e[:, 0]
    series["e_l"] = hist.e[:, 1]
    series["lambda_min"] = hist.lambda_min
    write_series_mcap(str(path), hist.t, series, force=force, metadata={"result": to_json_text(result.to_dict())})


def progress(label: str):
    """(callback(done, total), finish): a rich progress bar on stderr, shown when stderr is a terminal for logs of a
    million samples or more (10,000 without numba, whose plain-Python estimator takes about 0.3 ms a sample); else
    no-ops."""
    if not sys.stderr.isatty():
        return None, lambda: None
    from wmrid.core.jit import COMPILED

    shown_from = 1_000_000 if COMPILED else 10_000
    state: dict = {}

    def update(done: int, total: int) -> None:
        if total < shown_from:
            return
        if not state:
            from rich.progress import Progress

            bar = Progress(console=stderr_console(), transient=True)
            state["bar"], state["task"] = bar, bar.add_task(label, total=total)
            bar.start()
        state["bar"].update(state["task"], completed=done)

    def finish() -> None:
        if state:
            state["bar"].stop()

    return update, finish


@contextlib.contextmanager
def activity(label: str) -> Iterator[Callable[[str], None]]:
    """A transient spinner on stderr while a command works, shown only when stderr is a terminal; yields
    ``stage(text)``, which says what it is doing now ("label: text")."""
    if not sys.stderr.isatty():
        yield lambda text: None
        return
    from rich.status import Status

    status = Status(label, console=stderr_console())
    status.start()
    try:
        yield lambda text: status.update(f"{label}: {text}")
    finally:
        status.stop()


def on_stdout(output: Any) -> bool:
    """Whether ``-o`` named standard output (``-``, /dev/stdout, /dev/fd/1: :func:`wmrid.runtime.atomic.stream_fd`)."""
    from wmrid.runtime.atomic import stream_fd

    return output is not None and stream_fd(str(output)) == 1
