"""The ``wmrid`` application and its entry point: the Typer app the commands join, and :func:`main`.

Imports inside functions: start-up time (numpy, pandas, numba, rich are imported inside the commands so that
``wmrid --help`` answers at once).  :func:`main` is the one place that maps errors to exit codes and messages.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import os
import signal
import sys
import warnings
from collections.abc import Callable
from typing import Annotated, Any

import typer

from wmrid import __version__
from wmrid.cli.help import Group
from wmrid.core.errors import ExitStatus, ReaderGone, WmridError, option_style

app = typer.Typer(
    name="wmrid",
    cls=Group,
    help="Identify the dynamic parameters of differential-drive wheeled mobile robots from their logs "
    "(Hoang & Kang 2015).",
    no_args_is_help=True,
    add_completion=True,
    pretty_exceptions_enable=False,
    rich_markup_mode="rich",  # the option panels; every help text is escaped first (:func:`_verbatim_help`)
)


#: The arguments of the command line being run (for a report's reproducibility block).
_invocation: contextvars.ContextVar[tuple[str, ...]] = contextvars.ContextVar("wmrid_invocation", default=())


def invocation() -> str:
    """The command line being run, as a shell would take it back: ``wmrid report run.mcap -o r.html``."""
    import shlex

    return shlex.join(["wmrid", *_invocation.get()])


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


def _notes_in_one_line(show: Callable[..., None]) -> Callable[..., None]:
    """``warnings.showwarning`` that says wmrid's :class:`~wmrid.core.jit.PerformanceWarning` as "wmrid: note: ..."
    on stderr, the first one only (Python's own form names a file and a line of wmrid's), and leaves any other warning
    to ``show``."""

    said = []

    def shown(message: Any, category: type[Warning], *args: Any, **kwargs: Any) -> None:
        if category.__name__ == "PerformanceWarning" and category.__module__ == "wmrid.core.jit":
            if not said:  # once per command: compare's methods, monitor's windows would each say it again
                said.append(message)
                sys.stderr.write(_said(f"wmrid: note: {_one_line(str(message))}"))
        else:
            show(message, category, *args, **kwargs)

    return shown


def main(argv: list[str] | None = None) -> None:
    """Entry point: run the app and map every outcome to one exit code and at most one stderr line.

    Exit codes: 0 success, 1 no result (or an output that could not be written), 2 usage or unreadable input,
    128 + the signal for Ctrl-C, SIGTERM and SIGHUP (130, 143, 129; temporary files removed either way)."""
    from wmrid.runtime import interrupts

    previous: dict[int, object] = {}
    try:  # a stop before the command runs (its modules still importing): one line, nothing written
        from wmrid.cli import (  # noqa: F401  (their commands join ``app`` on import)
            export_commands,
            fleet_commands,
            identify_commands,
            live_commands,
            plan_commands,
            sim_commands,
        )
        from wmrid.cli.streams import finish_output, guard
        from wmrid.runtime.atomic import clear_inputs, track_inputs

        previous = interrupts.install()  # Ctrl-C is deferred while numba compiles (an interrupt there crashes LLVM)
        if argv is None:  # the command-line process: a signal that finds it stuck in compiled code still ends it
            interrupts.start_watchdog()
            from wmrid.runtime.limits import one_blas_thread, tune_malloc

            tune_malloc()  # large arrays from the heap, not mapped afresh each time (a process of one command)
            one_blas_thread()  # before numpy loads OpenBLAS: small calls, whose spinning workers took wmrid's cores
        saved = guard()  # a failing stdout is an error naming it; a failing stderr never changes the outcome
    except KeyboardInterrupt:
        code = interrupts.exit_code() if previous else 130  # SIGTERM once the handlers are in: 143
        if previous:
            interrupts.restore(previous)
        sys.stderr.write(f"wmrid: {_stopped_by() if previous else 'interrupted'}; no output was written\n")
        raise SystemExit(code) from None
    args = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in args
    if debug:  # accepted anywhere on the line, not only before the command
        args = ["--debug", *[a for a in args if a != "--debug"]]
    token = _invocation.set(tuple(a for a in args if a != "--debug"))
    try:
        track_inputs()  # an output that is one of the command's inputs is refused
        try:
            from wmrid.runtime.limits import memory_budget

            if not {"--help", "-h", "--version"} & set(args):
                memory_budget()  # a malformed WMRID_MEMORY_BUDGET is a usage error whatever the command reads
            with option_style("flag"), warnings.catch_warnings():  # flags as typed; notes in one line
                warnings.showwarning = _notes_in_one_line(warnings.showwarning)
                rv = command().main(args=args, prog_name="wmrid", standalone_mode=False)
            finish_output()
        finally:
            stopped = interrupts.disarm()  # a stop dropped in a callback, or still waiting, when the command ended
            clear_inputs()
        code = rv if isinstance(rv, int) else ExitStatus.OK
        if code == ExitStatus.INTERRUPTED or (stopped and code < 128):  # Typer turns Ctrl-C into an exit code of 130
            code = interrupts.exit_code()
            sys.stderr.write(f"wmrid: {_stopped_by()}; {_kept()}\n")
    except KeyboardInterrupt:
        sys.stderr.write(f"wmrid: {_stopped_by()}; {_kept()}\n")
        code = interrupts.exit_code()
    except WmridError as exc:
        if debug:
            _leave(argv, saved, previous)
            raise
        sys.stderr.write(_said(f"wmrid: error: {_one_line(str(exc))}"))
        code = exc.exit_status
    except (BrokenPipeError, ReaderGone):  # the reader (| head) has seen enough
        if argv is None:  # and nothing more is flushed into the closed pipe at exit
            with contextlib.suppress(OSError, ValueError):
                os.dup2(os.open(os.devnull, os.O_WRONLY), 1)
        code = ExitStatus.OK
    except MemoryError:
        if debug:
            _leave(argv, saved, previous)
            raise
        sys.stderr.write(_said(f"wmrid: error: {_out_of_memory()}"))
        code = ExitStatus.USAGE
    except Exception as exc:
        if type(exc).__name__ == "NoArgsIsHelpError":  # `wmrid COMMAND` without arguments: its help was shown
            code = ExitStatus.USAGE
        elif hasattr(exc, "format_message") and hasattr(exc, "exit_code"):  # a Click/Typer usage error
            sys.stderr.write(_said(f"wmrid: error: {_usage_line(exc)}"))
            code = ExitStatus.USAGE
        elif type(exc).__name__ == "Abort":
            code = interrupts.exit_code()
        elif debug:
            _leave(argv, saved, previous)
            raise
        else:  # the last resort: never a traceback without --debug
            sys.stderr.write(
                f"wmrid: internal error: {type(exc).__name__}: {_one_line(str(exc))} "
                "(run with --debug for the traceback)\n"
            )
            code = ExitStatus.NO_RESULT
    _invocation.reset(token)
    if argv is not None:  # called in-process: leave the caller's signal handlers and streams as they were
        _leave(argv, saved, previous)
        sys.exit(int(code))
    interrupts.disarm()
    for signum in (*interrupts.STOPPING, *interrupts.RETRIES):  # the outcome is decided: a late signal must not
        signal.signal(signum, signal.SIG_IGN)  # change it (nor the retry timer's, raising a stop past the handlers)
    if code >= 128:
        # Python remembers a KeyboardInterrupt that went through an embedded interpreter call (even one caught
        # later) and, at exit, kills itself with SIGINT instead of returning 130; leave at once instead.
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(int(code))
    sys.exit(int(code))


@functools.cache
def command() -> Any:
    """The click command Typer builds from ``app``, with every help text made verbatim (:func:`_verbatim_help`).

    Built once per process and kept: Typer's build reads the annotations of every command (about 50 ms), which an
    in-process caller running :func:`main` many times (the tests, a script) paid on every call.  Click makes a fresh
    context for each run, so nothing of one run is left on the command for the next."""
    from wmrid.cli import export_commands, fleet_commands, identify_commands, live_commands, plan_commands, sim_commands  # noqa: F401  (their commands join ``app`` on import)

    root = typer.main.get_command(app)
    _verbatim_help(root)
    _paths_read_by_wmrid(root)
    return root


def _paths_read_by_wmrid(cmd: Any) -> None:
    """Turn off Typer's own readability check of every ``Path`` option and argument of ``cmd`` and its subcommands:
    a file that cannot be read is then said by wmrid's reader, in one line naming it and the fix (Typer printed a
    usage block ending "Invalid value for '--truth': path '...' is not readable.")."""
    for param in getattr(cmd, "params", []):
        info = getattr(getattr(param, "type_descriptor", None), "parameter_info", None)
        if getattr(info, "readable", False):
            info.readable = False
    for sub in getattr(cmd, "commands", {}).values():
        _paths_read_by_wmrid(sub)


def _verbatim_help(cmd: Any) -> None:
    """Escape Rich markup in the help of ``cmd``, its options and its subcommands: the help is rendered with Rich
    (for the option panels), and texts such as '[m11 m12 ...]' or '[i]' are data, not styles."""
    from rich.markup import escape

    for attr in ("help", "epilog", "short_help"):
        if getattr(cmd, attr, None):
            setattr(cmd, attr, escape(getattr(cmd, attr)))
    if getattr(cmd, "help", None):  # a docstring's paragraphs flow: Rich kept its line breaks mid-sentence
        cmd.help = "\n\n".join(" ".join(paragraph.split()) for paragraph in cmd.help.split("\n\n"))
    for param in getattr(cmd, "params", []):
        if getattr(param, "help", None):
            param.help = escape(param.help)
    for sub in getattr(cmd, "commands", {}).values():
        _verbatim_help(sub)


def _leave(argv: list[str] | None, saved: Any, previous: Any) -> None:
    """In-process (``argv`` given): put back the caller's streams and signal handlers."""
    if argv is None:
        return
    from wmrid.cli.streams import unguard
    from wmrid.runtime import interrupts

    unguard(saved)
    interrupts.restore(previous)


def _out_of_memory() -> str:
    """The line for a MemoryError: the inputs the command named (its arguments that are existing paths, or "-"), the
    budget, and the address-space cap when there is one."""
    from wmrid.runtime.limits import ENV, address_space_cap, describe, memory_budget

    named = [a for a in _invocation.get() if a == "-" or (not a.startswith("-") and os.path.exists(a))]
    inputs = ", ".join("standard input" if a == "-" else a for a in named) or "the input"
    try:
        budget = f"the memory budget is {describe(memory_budget())} ({ENV})"
    except WmridError:
        budget = f"{ENV} is malformed"
    cap = address_space_cap()
    limit = f" under an address-space cap of {describe(cap)} (ulimit -v)" if cap is not None else ""
    return (
        f"out of memory reading {inputs}; {budget}{limit}: an endless source (/dev/zero, yes |)? save the log to a "
        f"file, or set {ENV} lower than the memory there is"
    )


def _usage_line(exc: Any) -> str:
    """A command-line usage error (an unknown option, a value that does not parse, a missing argument) as one line
    that names the fix, instead of click's usage block: "No such option: --nope ...; see wmrid identify --help"."""
    context = getattr(exc, "ctx", None)
    where = getattr(context, "command_path", None) or "wmrid"
    return f"{_one_line(exc.format_message()).rstrip('.')}; see {where} --help"


def _kept() -> str:
    """What a stopped command leaves: the files it wrote completely before the stop (a fleet's table), or none."""
    from wmrid.runtime.atomic import written

    done = written()
    return f"wrote {', '.join(done)} before the stop" if done else "no output was written"


def _stopped_by() -> str:
    from wmrid.runtime import interrupts

    received = interrupts.received
    if received is None or received == signal.SIGINT:
        return "interrupted"
    return f"terminated by {signal.Signals(received).name}"


def _said(line: str) -> str:
    """An error line as written to stderr: one line in a pipe or a file (for scripts and logs); on a terminal wrapped at
    its width, at word boundaries, the lines after the first indented (a terminal broke it mid-word)."""
    import textwrap

    try:
        terminal = sys.stderr.isatty()
    except (AttributeError, ValueError, OSError):
        terminal = False
    if not terminal:
        return line + "\n"
    columns = os.environ.get("COLUMNS", "")
    if columns.isdigit() and int(columns) > 0:  # as the terminal or the user says, as Rich reads it
        width = int(columns)
    else:
        try:
            width = os.get_terminal_size(sys.stderr.fileno()).columns  # the terminal stderr is on
        except OSError:
            width = 80
    width = max(width, 40)
    lines = textwrap.wrap(line, width=width, subsequent_indent="  ", break_long_words=False, break_on_hyphens=False)
    return "\n".join(lines) + "\n"


def _one_line(text: str) -> str:
    return " ".join(text.split())
