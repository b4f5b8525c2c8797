"""Running the ``wmrid`` command line from the tests (a helper module, not a test module).

:func:`wmrid` runs it in this process through its entry point :func:`wmrid.cli.main` (about 0.1 s of overhead); the
standard streams are swapped for in-memory ones, so it answers like a process: exit code, stdout and stderr bytes.
:func:`process` starts a real ``python -m wmrid`` (about 2 s to import), for what only a process shows: the entry
point itself, signals, pipes whose other end closes, output written straight to file descriptor 1 (``-o -``,
``/dev/stdout``), the signal watchdog and exits at 128 + the signal, the set-up ``import wmrid`` does once per
process (address-space cap, numba's cache folder), an inherited standard input (here: the bytes given, else empty).
"""

from __future__ import annotations

import contextlib
import io
import os
import subprocess
import sys
import warnings
from pathlib import Path

from wmrid.cli import main

#: The terminal width both runners give rich, so that tables wrap the same way.
COLUMNS = "100"


@contextlib.contextmanager
def _environment(cwd: Path | None, columns: str):
    saved_columns, saved_cwd = os.environ.get("COLUMNS"), os.getcwd()
    os.environ["COLUMNS"] = columns
    if cwd is not None:
        os.chdir(cwd)
    try:
        yield
    finally:
        if saved_columns is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = saved_columns
        os.chdir(saved_cwd)


def wmrid(
    *args: str, stdin: bytes | None = None, cwd: Path | None = None, columns: str = COLUMNS
) -> subprocess.CompletedProcess:
    """``wmrid ARGS`` in this process: (returncode, stdout bytes, stderr bytes) as a CompletedProcess; ``columns``
    the terminal width rich sees."""
    out, err = io.BytesIO(), io.BytesIO()
    streams = (
        io.TextIOWrapper(io.BytesIO(stdin or b""), encoding="utf-8"),
        io.TextIOWrapper(out, encoding="utf-8", write_through=True),
        io.TextIOWrapper(err, encoding="utf-8", write_through=True),
    )
    saved = sys.stdin, sys.stdout, sys.stderr
    sys.stdin, sys.stdout, sys.stderr = streams
    code: int | str | None = 0
    try:
        # a process's warning filters, not the test run's "error" (which would turn a warning into an exception
        # that the code under test might catch and act on)
        with _environment(cwd, columns), warnings.catch_warnings():
            warnings.resetwarnings()
            main([str(a) for a in args])
    except SystemExit as stop:
        code = stop.code
        if isinstance(code, str):  # as the interpreter does: the message on stderr, exit 1
            streams[2].write(code + "\n")
    finally:
        for stream in streams[1:]:
            with contextlib.suppress(ValueError):
                stream.flush()
        sys.stdin, sys.stdout, sys.stderr = saved
    returncode = code if isinstance(code, int) else (0 if code is None else 1)
    return subprocess.CompletedProcess(["wmrid", *args], returncode, out.getvalue(), err.getvalue())


def process(*args: str, stdin: bytes | None = None, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """``python -m wmrid ARGS`` as a real process with bytes in and out, 100 columns wide, at most 300 s."""
    env = dict(os.environ, COLUMNS=COLUMNS)
    return subprocess.run(
        [sys.executable, "-m", "wmrid", *args], input=stdin, capture_output=True, cwd=cwd, env=env, timeout=300
    )


def text(proc: subprocess.CompletedProcess) -> subprocess.CompletedProcess:
    """The same outcome with stdout and stderr decoded (UTF-8)."""
    return subprocess.CompletedProcess(proc.args, proc.returncode, proc.stdout.decode(), proc.stderr.decode())


def assert_clean_error(proc: subprocess.CompletedProcess, code: int, *needles: str) -> str:
    """The run failed with exit ``code`` and exactly one stderr line holding every needle; that line."""
    err = proc.stderr.decode()
    assert proc.returncode == code, err
    assert "Traceback" not in err
    assert proc.stdout == b""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]
