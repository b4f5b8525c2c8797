"""The command line: a thin translation of flags into library calls (:mod:`wmrid.api`).

``main`` is the console script's entry point; the Typer application is imported only when it runs, so that
importing :mod:`wmrid.cli` costs nothing.

Imports inside functions: start-up time (``wmrid --help`` and each command load only what that command runs).
"""

from __future__ import annotations


def main(argv: list[str] | None = None) -> None:
    """Run ``wmrid`` with ``argv`` (default: the process's arguments); exits through SystemExit.

    Ctrl-C while the application is still being imported (before it installs its own handling; on a loaded machine
    that took over 0.5 s, and the default handler printed a traceback from inside typer's import) ends the run the
    way a later one does: one line, exit 130, nothing written."""
    try:
        from wmrid.cli.app import main as run
    except KeyboardInterrupt:
        import sys

        sys.stderr.write("wmrid: interrupted; no output was written\n")
        raise SystemExit(130) from None
    run(argv)
