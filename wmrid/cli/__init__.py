"""The command line: a thin translation of flags into library calls (:mod:`wmrid.api`).

``main`` is the console script's entry point; the Typer application is imported only when it runs, so that
importing :mod:`wmrid.cli` costs nothing."""

from __future__ import annotations


def main(argv: list[str] | None = None) -> None:
    """Run ``wmrid`` with ``argv`` (default: the process's arguments); exits through SystemExit."""
    from wmrid.cli.app import main as run

    run(argv)
