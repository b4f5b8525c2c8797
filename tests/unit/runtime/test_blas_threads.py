"""One BLAS thread in the command-line process (:func:`wmrid.runtime.limits.one_blas_thread`), unless the user set a
count; each case runs in its own process (the count is read when numpy loads OpenBLAS)."""

from __future__ import annotations

import os
import subprocess
import sys

from locations import ROOT_DIR

from wmrid.runtime.limits import BLAS_THREAD_VARIABLES

SHOW = "import os, sys; from wmrid.cli import main; sys.argv = ['wmrid', '--version']\n" + (
    "try:\n    main()\nexcept SystemExit:\n    pass\nprint(os.environ.get('OPENBLAS_NUM_THREADS'))"
)


def _count(extra: dict[str, str]) -> str:
    env = {k: v for k, v in os.environ.items() if k not in BLAS_THREAD_VARIABLES} | extra
    command = [sys.executable, "-c", SHOW]
    out = subprocess.run(command, cwd=ROOT_DIR, env=env, capture_output=True, text=True, check=True)
    return out.stdout.strip().splitlines()[-1]


def test_the_command_line_uses_one_blas_thread_unless_the_user_set_a_count():
    assert _count({}) == "1"
    assert _count({"OPENBLAS_NUM_THREADS": "2"}) == "2"
    assert _count({"OMP_NUM_THREADS": "4"}) == "None"
