"""Where the tests find the repository's files, wherever a test module sits under ``tests/`` (a helper module)."""

from __future__ import annotations

from pathlib import Path

#: The checkout's root (the folder holding pyproject.toml).
ROOT_DIR = Path(__file__).resolve().parents[1]
#: The tests' own data files.
DATA_DIR = ROOT_DIR / "tests" / "data"
