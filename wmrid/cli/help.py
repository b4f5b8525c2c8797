"""Help that fits a terminal: ``wmrid COMMAND --help`` shows the options most runs need, and each panel of detail (the
log's input, the observer: :data:`wmrid.cli.options.FOLDED_PANELS`) folds into one line that says how many options it
holds; ``--help-all`` shows every option.  The options are the same either way (the reference lists them all).

Imports inside functions: start-up time (Typer's flag type only when a command's parameters are listed)."""

from __future__ import annotations

from typing import Any

from typer.core import TyperCommand, TyperGroup, TyperOption

try:
    from typer import _click as click  # Typer 0.29 and later: its own copy of click
except ImportError:  # a Typer on click
    import click  # type: ignore[no-redef]

from wmrid.cli.options import FOLDED_PANELS

#: The context's key that says ``--help-all`` was given.
_ALL = "wmrid.help_all"


def _show_all(ctx: Any, param: Any, value: bool) -> None:
    if value and not ctx.resilient_parsing:
        ctx.meta[_ALL] = True
        click.echo(ctx.get_help(), color=ctx.color)
        ctx.exit()


def _help_all_option() -> Any:
    """The ``--help-all`` flag, made as Typer makes its own ``--help`` (Typer 0.29 and later: its own parser and flag
    type; before: click's option)."""
    text = "Show every option, those of the folded panels too, and exit."
    try:
        from typer._coercion import bool_flag_type_descriptor  # Typer's flag type, as its own --help uses
    except ImportError:  # a Typer on click
        return click.Option(
            ["--help-all"], is_flag=True, expose_value=False, is_eager=True, callback=_show_all, help=text
        )
    return TyperOption(
        param_decls=["--help-all"], is_flag=True, expose_value=False, is_eager=True, required=False,
        callback=_show_all, help=text, type_descriptor=bool_flag_type_descriptor(),
    )  # fmt: skip


class Command(TyperCommand):
    """A command whose ``--help`` folds the panels of detail (:mod:`wmrid.cli.help`)."""

    _folding: tuple[Any, ...] = ()  # the options hidden while --help is written

    def _folded(self) -> list[Any]:
        panels = [p for p in self.params if getattr(p, "rich_help_panel", None) in FOLDED_PANELS]
        return [p for p in panels if not p.hidden or p in self._folding]

    _help_all: Any = None

    def get_params(self, ctx: Any) -> list[Any]:
        params = super().get_params(ctx)
        if not self._folded():
            return params
        if self._help_all is None:  # one object: click orders the eager callbacks by identity
            self._help_all = _help_all_option()
        return [*params[:-1], self._help_all, params[-1]]  # before --help, which click puts last

    def format_help(self, ctx: Any, formatter: Any) -> None:
        for p in self.get_params(ctx):
            _plain_type(p)
        folded = [] if ctx.meta.get(_ALL) else self._folded()
        if not folded:
            super().format_help(ctx, formatter)
            return
        counts: dict[str, int] = {}
        for p in folded:
            counts[p.rich_help_panel] = counts.get(p.rich_help_panel, 0) + 1
        panels = "; ".join(f"{panel}: {n} options" for panel, n in counts.items())
        saved = self.epilog
        line = f"Folded: {panels}. See them: {ctx.command_path} --help-all"
        self.epilog = f"{saved}\n\n{line}" if saved else line
        self._folding = tuple(folded)
        for p in folded:
            p.hidden = True
        try:
            super().format_help(ctx, formatter)
        finally:
            for p in folded:
                p.hidden = False
            self._folding = ()
            self.epilog = saved


def _plain_type(param: Any) -> None:
    """``param``'s type label in the help as a user needs it: none for a flag (Typer writes ``<bool>`` beside
    ``--force``, which takes no value) nor for an argument that repeats (``<list[str]>`` beside ``LOG``: the usage line
    says ``{LOG}...``); a repeatable option's element type, repeated (``<str>...``).  Set once on the parameter; a
    Typer without the type column is left as it is."""
    shown = getattr(param, "display_type_rich", None)
    if shown is None or getattr(param, "_wmrid_plain_type", False):
        return

    def plain(ctx: Any) -> str | None:
        if getattr(param, "is_flag", False):
            return None
        label = shown(ctx)
        if label is None or not label.startswith("<list["):
            return label
        if param.param_type_name == "argument":
            return None  # the usage line says {LOG}...
        return "<" + label[len("<list[") : -2] + ">..."  # a repeatable option: its element's type, repeated

    param.display_type_rich = plain
    param._wmrid_plain_type = True


class Group(TyperGroup):
    """The ``wmrid`` group: its ``--help`` lists the commands in the order a user meets them
    (:data:`COMMAND_ORDER`: identify first, the fleet last), with :func:`_plain_type`'s labels."""

    def list_commands(self, ctx: Any) -> list[str]:
        names = super().list_commands(ctx)
        rank = {name: i for i, name in enumerate(COMMAND_ORDER)}
        return sorted(names, key=lambda n: (rank.get(n, len(rank)), names.index(n)))

    def format_help(self, ctx: Any, formatter: Any) -> None:
        for p in self.get_params(ctx):
            _plain_type(p)
        super().format_help(ctx, formatter)


#: The commands in the order ``wmrid --help`` and the reference list them: the main job, then reading, comparing,
#: simulating and designing a drive, following a robot, handing the model on, fleets.
COMMAND_ORDER = (
    "identify", "inspect", "report", "compare", "simulate", "plan", "live", "monitor", "export", "fleet",
    "fleet-report",
)  # fmt: skip
