"""A ROS 2 sqlite3 recording that was not closed, its last messages still in the write-ahead log (``-wal``), as
rosbag2's "resilient" preset leaves it after a power loss (wmrid/io/bag/db3_wal.py).

The recordings are made here with Python's own sqlite3: a db3 written by rosbags' writer, part of its messages moved
into the WAL by a process that exits without a checkpoint.  The reference is SQLite's own recovery, on a copy of
the files (opened normally, SQLite replays the WAL): wmrid must read the same rows, leave the files as they were,
say what it recovered, and identify as from the whole recording.  rosbags, which opens the database immutable, sees
only the checkpointed part (checked, as the reason for this reader).
"""

from __future__ import annotations

import hashlib
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from locations import ROOT_DIR

import wmrid as api
from tests import bagutil
from wmrid.io.bag import db3_file
from wmrid.io.bag.db3_wal import wal_view

ROOT = ROOT_DIR
SAMPLE = ROOT / "sample_logs" / "paper_sinusoid.mcap"

_CRASHING_WRITER = """
import os, pickle, sqlite3, sys
path, rows_file, batches, autocheckpoint = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
rows = pickle.load(open(rows_file, "rb"))
con = sqlite3.connect(path)
con.execute(f"PRAGMA wal_autocheckpoint={autocheckpoint}")  # 0: never; else a checkpoint (and restart) past N pages
step = -(-len(rows) // batches)
for i in range(0, len(rows), step):  # one transaction a batch: pages rewritten by later ones
    con.executemany("INSERT INTO messages (id, topic_id, timestamp, data) VALUES (?, ?, ?, ?)", rows[i : i + step])
    con.commit()
os._exit(0)  # the power loss: no checkpoint, no close
"""


def _crashed(folder: Path, messages, kept: int, batches: int = 4, autocheckpoint: int = 0) -> Path:
    """A rosbag2 folder whose messages after the first ``kept`` are only in the db3's write-ahead log (with
    ``autocheckpoint`` pages, some of them checkpointed on the way, the log restarted over older frames)."""
    import pickle

    bagutil.write_rosbag2(folder, messages)
    db = next(folder.glob("*.db3"))
    con = sqlite3.connect(db)
    query = "SELECT id, topic_id, timestamp, data FROM messages WHERE id > ? ORDER BY id"
    rows = con.execute(query, (kept,)).fetchall()
    con.execute("DELETE FROM messages WHERE id > ?", (kept,))
    con.commit()
    con.execute("PRAGMA journal_mode=WAL")
    con.close()
    rows_file = folder.parent / f"{folder.name}.rows.pkl"
    rows_file.write_bytes(pickle.dumps(rows))
    subprocess.run(
        [sys.executable, "-c", _CRASHING_WRITER, str(db), str(rows_file), str(batches), str(autocheckpoint)], check=True
    )
    rows_file.unlink()
    assert Path(f"{db}-wal").stat().st_size > 0
    return folder


def _files(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


def _sqlite_recovery(folder: Path, tmp_path: Path) -> list[tuple]:
    """The messages as SQLite itself recovers them, from a copy of the files."""
    copy = tmp_path / "sqlite_copy"
    shutil.copytree(folder, copy)
    con = sqlite3.connect(next(copy.glob("*.db3")))
    try:
        return con.execute("SELECT id, topic_id, timestamp, data FROM messages ORDER BY id").fetchall()
    finally:
        con.close()


@pytest.fixture(scope="module")
def messages():
    return bagutil.recording(SAMPLE)[:6000]


@pytest.fixture(scope="module")
def crashed(tmp_path_factory, messages):
    return _crashed(tmp_path_factory.mktemp("wal") / "run", messages, kept=1500)


def test_the_rows_are_sqlites_own_recovery_and_the_files_are_left_alone(crashed, tmp_path):
    before = _files(crashed)
    db = str(next(crashed.glob("*.db3")))
    con = db3_file._connect(db)
    try:
        ours = list(con.execute("SELECT id, topic_id, timestamp, data FROM messages ORDER BY id"))
    finally:
        con.close()
    theirs = _sqlite_recovery(crashed, tmp_path)
    assert len(theirs) == 6000
    assert [tuple(r) for r in ours] == theirs
    assert _files(crashed) == before, "the recording's files were changed"
    view = wal_view(db)
    assert view is not None
    assert view.torn == 0


def test_a_crashed_recording_reads_and_identifies_as_the_whole_one(crashed, messages, tmp_path):
    """The log is the whole recording's, bit for bit, with a note saying what came from the write-ahead log; rosbags
    sees only the messages checkpointed before the crash."""
    from rosbags.highlevel import AnyReader

    whole = bagutil.write_rosbag2(tmp_path / "whole", messages)
    log, reference = api.read_log(str(crashed)), api.read_log(str(whole))
    for field in ("t", "eta", "tau"):
        assert np.array_equal(getattr(log, field), getattr(reference, field)), field
    (note,) = [n for n in log.notes if "write-ahead log" in n]
    assert "was not closed" in note
    assert [n for n in log.notes if n != note] == list(reference.notes)
    with AnyReader([crashed]) as reader:
        assert sum(1 for _ in reader.messages()) == 1500
    assert api.identify(str(crashed)).parameters == api.identify(str(whole)).parameters


def test_a_torn_last_frame_is_left_out_as_sqlite_leaves_it_out(crashed, tmp_path):
    """A crash in the middle of writing a frame: its checksum fails, and it and every frame after it are left out,
    as SQLite's own recovery leaves them out."""
    folder = tmp_path / "torn"
    shutil.copytree(crashed, folder)
    wal = next(folder.glob("*.db3-wal"))
    data = bytearray(wal.read_bytes())
    page = int.from_bytes(data[8:12], "big")
    frame = 24 + page
    frames = (len(data) - 32) // frame
    hit = 32 + (frames - 3) * frame + 24 + page // 2  # inside the third frame from the end
    data[hit] ^= 0xFF
    wal.write_bytes(bytes(data))
    db = str(next(folder.glob("*.db3")))
    view = wal_view(db)
    assert view is not None
    assert view.frames + view.torn == frames
    assert view.torn >= 3
    con = db3_file._connect(db)
    try:
        ours = [tuple(r) for r in con.execute("SELECT id, topic_id, timestamp, data FROM messages ORDER BY id")]
    finally:
        con.close()
    theirs = _sqlite_recovery(folder, tmp_path)
    assert 1500 <= len(theirs) < 6000
    assert ours == theirs
    assert "left out" in view.note()


def test_no_wal_or_an_empty_or_foreign_one_is_no_view(crashed, tmp_path):
    folder = tmp_path / "other"
    shutil.copytree(crashed, folder)
    db = next(folder.glob("*.db3"))
    wal = Path(f"{db}-wal")
    wal.write_bytes(b"")
    assert wal_view(str(db)) is None
    wal.write_bytes(b"not a write-ahead log" * 10)
    assert wal_view(str(db)) is None
    wal.unlink()
    assert wal_view(str(db)) is None
    log = api.read_log(str(folder))  # the checkpointed part alone, as before
    assert len(log) == 1500
    assert not any("write-ahead" in n for n in log.notes)


def test_read_through_rosbags_the_log_left_out_is_said(crashed, monkeypatch):
    """Where rosbags reads the recording (compressed, or overlapping files), the write-ahead log's messages are left
    out, and a note says so instead of nothing."""
    monkeypatch.setattr(db3_file, "db3_files", lambda paths: None)
    log = api.read_log(str(crashed))
    assert len(log) == 1500
    (note,) = [n for n in log.notes if "write-ahead log" in n]
    assert "are left out" in note


def test_a_log_restarted_by_checkpoints_reads_as_sqlite_recovers_it_and_nothing_is_called_torn(messages, tmp_path):
    """rosbag2's resilient preset keeps SQLite's automatic checkpoints: the log restarts over older frames (other
    salts, already in the database).  Those are neither read nor said to be left out."""
    folder = _crashed(tmp_path / "run", messages, kept=1000, batches=40, autocheckpoint=20)
    db = str(next(folder.glob("*.db3")))
    view = wal_view(db)
    assert view is not None
    assert view.torn == 0
    in_file = (Path(f"{db}-wal").stat().st_size - 32) // (24 + view.page_size)
    assert in_file > view.frames, "no older frames after the restarted log: the case is not made"
    con = db3_file._connect(db)
    try:
        ours = [tuple(r) for r in con.execute("SELECT id, topic_id, timestamp, data FROM messages ORDER BY id")]
    finally:
        con.close()
    assert ours == _sqlite_recovery(folder, tmp_path)
    assert len(ours) == 6000
    assert "left out" not in view.note()


def test_a_recording_reached_through_a_symbolic_link(crashed, tmp_path):
    """A folder or a db3 reached through a symbolic link reads its log as well (SQLite's default VFS answers a
    link with a code apsw took for an error, and the recording went to rosbags: 1500 of 6000 messages)."""
    (tmp_path / "linked").symlink_to(crashed, target_is_directory=True)
    assert len(api.read_log(str(tmp_path / "linked"))) == 6000
    db = next(crashed.glob("*.db3"))
    files = tmp_path / "files"
    files.mkdir()
    for suffix in ("", "-wal"):
        (files / f"{db.name}{suffix}").symlink_to(f"{db}{suffix}")
    log = api.read_log(str(files / db.name))
    assert len(log) == 6000
    assert any("write-ahead log" in n for n in log.notes)


def test_an_unreadable_log_is_said(crashed, monkeypatch):
    """A write-ahead log that cannot be read (permissions): the database alone is read, and a note says what may be
    missing instead of nothing."""
    from wmrid.io.bag import db3_wal

    def refused(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(db3_wal, "_cache", {})
    monkeypatch.setattr(db3_wal, "open_regular", refused)  # as root, a chmod 000 file is still read
    log = api.read_log(str(crashed))
    assert len(log) == 1500
    (note,) = [n for n in log.notes if "write-ahead log" in n]
    assert "could not be read (Permission denied)" in note
    assert "may be missing" in note
