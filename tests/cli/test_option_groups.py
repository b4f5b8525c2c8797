"""The flags declared once (:mod:`wmrid.cli.groups`): made from the library's option objects, defaults included (which
command offers which is tests/cli/test_cli_options.py's)."""

from __future__ import annotations

from dataclasses import fields

import pytest
import typer.main

from wmrid.api.inputs import LogOptions
from wmrid.cli.app import app
from wmrid.cli.groups import FIT_FLAGS, LOG_FLAGS, OBSERVER_FLAGS
from wmrid.estimators.options import MethodOptions, ObserverOptions


def _commands() -> dict[str, set[str]]:
    from wmrid.cli import (  # noqa: F401  (their commands join ``app`` on import)
        export_commands,
        fleet_commands,
        identify_commands,
        live_commands,
        plan_commands,
        sim_commands,
    )

    group = typer.main.get_command(app)
    return {name: {p.name for p in command.params} for name, command in group.commands.items()}  # type: ignore[attr-defined]


def _flags(command_name: str) -> dict[str, object]:
    group = typer.main.get_command(app)
    return {p.name: p for p in group.commands[command_name].params}  # type: ignore[attr-defined]


@pytest.mark.parametrize("command", ["identify", "report", "compare", "fleet"])
def test_the_commands_that_run_a_classical_method_offer_its_flags(command: str) -> None:
    assert set(FIT_FLAGS.names) <= _commands()[command]


def test_export_s_check_log_is_read_with_the_log_flags() -> None:
    assert set(LOG_FLAGS.names) <= _commands()["export"]


@pytest.mark.parametrize(("group", "options"), [(LOG_FLAGS, LogOptions), (OBSERVER_FLAGS, ObserverOptions),
                                               (FIT_FLAGS, MethodOptions)])  # fmt: skip
def test_a_flag_s_default_is_the_library_s_default(group, options) -> None:
    """The defaults are read from the dataclass, never written twice: each flag's default, as the command line
    parses it, makes the library's default object."""
    flags = _flags("identify")
    values = {}
    for name in group.names:
        default = flags[name].default  # type: ignore[attr-defined]
        values[name] = default
    assert group.make(values) == options()
    assert {f.name for f in fields(options)} - set(group.flags) <= group.internal
