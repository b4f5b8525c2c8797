"""The terminal: the consoles every command prints through, and the few styles that carry meaning.

Data is printed verbatim: file names, topic names, notes and warnings may hold ``[``, ``]``, ``[/red]`` or
``[bold]``, so no console interprets Rich markup, and no highlighter colours numbers or slashes.  Colour is kept
for what it means (:data:`STYLES`): a warning, a flagged or poorly determined value, an impossible one.  Rich leaves
colour out when ``NO_COLOR`` is set, when ``TERM`` is ``dumb``, and when the output is not a terminal.
"""

from __future__ import annotations

from typing import Any

#: What each style means; nothing else is coloured.
STYLES = {
    "warning": "yellow",  # the word "warning:" before a warning
    "flagged": "yellow",  # a value whose std may not cover its error (the "!" mark)
    "impossible": "bold red",  # a value physics forbids (a negative friction or mass)
    "dim": "dim",  # units, a missing reference value
}


def console(*, stderr: bool = False) -> Any:
    """A rich Console that prints text as it is: no markup, no highlighting, no emoji codes."""
    from rich.console import Console  # rich (~20 ms): only when something is printed (a JSON run never loads it)

    return Console(stderr=stderr, markup=False, highlight=False, emoji=False)


def styled(text: str, meaning: str) -> Any:
    """``text`` in the style of ``meaning`` (a key of :data:`STYLES`), as a rich Text (never parsed as markup)."""
    from rich.text import Text  # rich: only when something is printed

    return Text(text, style=STYLES[meaning])


def warning(text: str, prefix: str = "warning") -> Any:
    """'warning: TEXT' with the word in the warning style and the text verbatim."""
    from rich.text import Text  # rich: only when something is printed

    return Text.assemble((f"{prefix}:", STYLES["warning"]), " ", text)


def print_table(
    console: Any, header: list[str], rows: list[list[Any]], *, title: str | None = None, numeric: tuple[int, ...] = (),
    fold: tuple[int, ...] = (),
) -> None:  # fmt: skip
    """Rows under ``header`` as a table that fits the console: the title on its own line (wrapped at the terminal's
    width, not the table's), then the table; when it is wider than the terminal, in slices of columns, each
    repeating the first (the row's name), so that no number is cut or broken.  Column 0 and the ``fold`` columns
    (names a user copies: topics, joints) fold onto more lines where needed, never cut.  ``numeric`` columns are
    right-aligned.  Cells are strings or rich Text (a styled value)."""
    if title:
        console.print(title, style="bold")
    if not rows:
        return
    slices: list[list[int]] = []
    current: list[int] = []
    for col in range(1, len(header)):
        trial = [*current, col]
        if current and _width(console, header, rows, [0, *trial], numeric, fold) > console.width:
            slices.append(current)
            trial = [col]
        current = trial
    slices.append(current)
    for i, cols in enumerate(slices):
        if i:
            console.print()
        console.print(_table(console, header, rows, [0, *cols], numeric, fold))


def _table(console: Any, header, rows, cols, numeric, fold) -> Any:
    from rich import box  # rich: only when a table is printed
    from rich.table import Table  # rich (~15 ms): only when a table is printed

    table = Table(box=box.SIMPLE_HEAD, pad_edge=False)
    for c in cols:
        folds = c == 0 or c in fold
        table.add_column(header[c], justify="right" if c in numeric else "left", no_wrap=not folds,
                         overflow="fold" if folds else "ellipsis",
                         max_width=max(12, console.width // 2) if folds and len(cols) > 1 else None)  # fmt: skip
    for row in rows:
        table.add_row(*(row[c] for c in cols))
    return table


def _width(console: Any, header, rows, cols, numeric, fold) -> int:
    from rich.measure import Measurement  # rich: only when a table is printed

    unbounded = console.options.update_width(1 << 20)  # a table's measure is otherwise capped at the console's width
    return Measurement.get(console, unbounded, _table(console, header, rows, cols, numeric, fold)).maximum
