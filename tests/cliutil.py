"""Running the real ``wmrid`` command line in a subprocess, for the tests that do (not a test module)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path


def wmrid(*args: str, stdin: bytes | None = None, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """``python -m wmrid ARGS`` with bytes in and out, 100 columns wide, at most 300 s."""
    env = dict(os.environ, COLUMNS="100")
    return subprocess.run(
        [sys.executable, "-m", "wmrid", *args], input=stdin, capture_output=True, cwd=cwd, env=env, timeout=300
    )


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
