"""Reliability, round three (issue 30): db3 rows, compressed CSV and ROS 1 chunks bounded by the memory budget, and
one clear line where an "internal error" or a library's message came out (a db3's text time stamps, a folder's empty
``.bag``, a fleet table's string columns, a robot file's 5000-digit integer or 10,000 casters, a file without read
permission, an output in a read-only folder, ``/dev/zero`` as the log).

Every input is a real file: sqlite databases written by rosbags and changed with SQL, ROS 1 bags whose chunks are
written record by record, xz files, unreadable files made so by dropping the process's power to override file
permissions (as root, ``chmod 000`` alone does not stop a read).  Large inputs are made small by a small
``WMRID_MEMORY_BUDGET``; where memory is the point, a real process's peak resident size is measured.
"""

from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from tests.cliutil import assert_clean_error, wmrid
from tests.test_side_files import run

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_logs" / "paper_sinusoid.mcap"
CSV = ROOT / "sample_logs" / "paper_sinusoid.csv"


@pytest.fixture(scope="module")
def small_db3(tmp_path_factory) -> Path:
    """A rosbag2 sqlite3 recording of the sample's first 6 s (6,001 JointState messages), written by rosbags."""
    from tests import bagutil

    messages = bagutil.recording(SAMPLE)
    first = messages[0].log_ns
    folder = bagutil.write_rosbag2(
        tmp_path_factory.mktemp("db3") / "rec", [m for m in messages if m.log_ns - first < 6e9]
    )
    return next(folder.glob("*.db3"))


def _changed(db3: Path, to: Path, *sql: str) -> Path:
    """A copy of ``db3`` at ``to`` with the SQL statements applied."""
    shutil.copyfile(db3, to)
    with sqlite3.connect(to) as db:
        for statement in sql:
            db.execute(statement)
    return to


def _series(path: Path):
    from wmrid.io.bag.reader import read_bag

    contents = read_bag([str(path)])
    (series,) = contents.joints.values()
    return contents, series


# ---------------------------------------------------------------------------------------------------------------
# db3 rows bounded by the budget, as MCAP records are


def test_a_db3_row_beyond_the_budget_is_skipped_unread_and_a_large_one_read_alone(tmp_path, small_db3, monkeypatch):
    monkeypatch.setenv("WMRID_MEMORY_BUDGET", "8M")  # rows inline up to 64 KiB; larger ones fetched one by one
    _, plain = _series(small_db3)
    padded = _changed(  # trailing bytes after a JointState's effort are ignored: the same messages
        small_db3, tmp_path / "padded.db3",
        "UPDATE messages SET data = data || zeroblob(100000) WHERE id IN (100, 101, 3000)",
        "UPDATE messages SET data = data || zeroblob(300000) WHERE id = 6001",
    )  # fmt: skip
    contents, series = _series(padded)
    assert not contents.notes
    np.testing.assert_array_equal(series.velocity, plain.velocity)
    np.testing.assert_array_equal(series.log_ns, plain.log_ns)
    huge = _changed(small_db3, tmp_path / "huge.db3", "UPDATE messages SET data = data || zeroblob(9e6) WHERE id = 50")
    contents, series = _series(huge)
    assert len(series.log_ns) == len(plain.log_ns) - 1
    (note,) = [n for n in contents.notes if "skipped unread" in n]
    assert note.startswith(f"{huge}: a message of 8.58 MiB on /joint_states (stamp ")
    assert note.endswith("beyond the memory budget of 8 MiB (WMRID_MEMORY_BUDGET), was skipped unread")


def test_a_db3_row_beyond_the_budget_leaves_memory_alone(tmp_path, small_db3):
    """Was exit 0 at 1.33 GB resident for a 300 MB row under a 256 MiB budget (fetched, then copied: 4 times its
    size); here a 60 MB row under a 16 MiB budget."""
    big = _changed(small_db3, tmp_path / "big.db3", "INSERT INTO messages (topic_id, timestamp, data) VALUES "
                   "(1, 1700000003000000500, zeroblob(60000000))")  # fmt: skip
    done = run("inspect", str(big), budget="16M")
    assert done.returncode == 0, done.stderr
    assert "a message of 57.2 MiB on /joint_states (stamp 1700000003000000500 ns), beyond the memory" in done.stdout
    assert done.peak_rss < 200 << 20, done.peak_rss


@pytest.mark.parametrize(
    ("sql", "needle"),
    [
        ("UPDATE messages SET timestamp = 'abc' WHERE id = 5", "holds a time stamp that is not an integer ('abc')"),
        ("UPDATE messages SET timestamp = x'00ff' WHERE id = 5", "a time stamp that is not an integer (b'\\x00\\xff')"),
        ("UPDATE messages SET data = 'text' WHERE id = 5", "its sqlite3 storage stopped reading"),
        ("UPDATE messages SET data = 5 WHERE id = 5", "its sqlite3 storage stopped reading"),
    ],
)
def test_a_db3_with_values_of_the_wrong_type_is_one_line(tmp_path, small_db3, sql, needle):
    db = _changed(small_db3, tmp_path / "odd.db3", sql)
    line = assert_clean_error(wmrid("identify", str(db)), 2, f"{db}: the recording is damaged", needle)
    assert "internal error" not in line  # was ValueError: invalid literal for int()


# ---------------------------------------------------------------------------------------------------------------
# A folder's recording files


def test_a_folder_with_an_empty_or_foreign_bag_is_one_line(tmp_path, small_db3):
    empty, foreign = tmp_path / "empty", tmp_path / "foreign"
    for folder in (empty, foreign):
        folder.mkdir()
    (empty / "x.bag").write_bytes(b"")
    (foreign / "a.bag").write_bytes(b"not a bag\n")
    shutil.copyfile(small_db3, foreign / "b.db3")
    assert_clean_error(wmrid("identify", str(empty)), 2, f"{empty}/x.bag: the file is empty (0 bytes)")
    # was: internal error: ReaderError: Unrecognized storage format '.bag'
    assert_clean_error(wmrid("inspect", str(foreign)), 2, f"{foreign}/a.bag: a .bag file that is not a ROS 1 bag")
