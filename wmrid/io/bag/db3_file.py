"""ROS 2 sqlite3 recordings (``.db3`` files, rosbag2 folders with sqlite3 storage, several of them in time order)
read by wmrid itself, block by block (:class:`Db3State`): the sqlite3 counterpart of
:mod:`wmrid.io.bag.ros1_file`.

rosbags' reader opens a ``.db3`` by counting every topic's messages with a join over the whole table (0.17-0.26 s
of a 1.2 s identify on a 600,000-message file, ``bench/speed/bench_bags.py``) and then hands out one message at a time
through generators.  Here the file is opened read-only with apsw (the SQLite binding rosbags itself uses), its
``topics`` and ``message_definitions`` tables give the topics, and one query in timestamp order (rosbags' order:
the ``timestamp_idx`` index) returns every message, with the bytes of the JointState topics only; the counts and
time ranges of the other topics come from the same pass.  The JointState messages are decoded as for rosbags'
reads (:class:`wmrid.io.bag.state._BagState`: the compiled CDR kernel, rosbags' deserialiser for the rest).

What this reader does not take -- a compressed recording, MCAP storage, a serialisation other than CDR, a file
that is not an SQLite database with rosbag2's tables, recordings that overlap in time -- :func:`db3_files` leaves to
rosbags (:class:`wmrid.io.bag.reader.BagFiles`), which reads all of them or says what is wrong.
"""

from __future__ import annotations

import itertools
import os
import urllib.request
from collections.abc import Generator, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from wmrid.core.errors import LogFormatError
from wmrid.io.bag.db3_wal import connect, wal_state
from wmrid.io.bag.state import BATCH, _BagState, _one_line, _Topic, storage_files
from wmrid.runtime.limits import describe

SQLITE_MAGIC = b"SQLite format 3\x00"
#: sqlite rows fetched at a time (below the garbage collector's threshold of 700 live allocations: holding a whole
#: batch of row tuples made Python's collector take 0.55 s of a 1.3 s read).
_ROWS = 256


@dataclass
class _File:
    """One .db3 file: its path, its topics as (topic id, name, type, definition), its first and last stamps (ns)."""

    path: str
    topics: list[tuple[int, str, str, str]]
    first: int | None
    last: int | None


def db3_files(paths: Sequence[str]) -> list[list[_File]] | None:
    """The recordings of ``paths`` (each a rosbag2 folder or a .db3 file) as lists of their .db3 files, recordings in
    time order and files in the recording's own order, when wmrid reads them itself; None when rosbags must (see
    the module docstring)."""
    recordings = []
    for path in paths:
        files = storage_files(path, "sqlite3", SQLITE_MAGIC)
        if files is None:
            return None
        opened = []
        for file in files:
            one = _describe(file)
            if one is None:
                return None
            opened.append(one)
        recordings.append(opened)
    spans = [_span(r) for r in recordings]
    order = sorted(range(len(recordings)), key=lambda i: spans[i][0])
    full = [i for i in order if spans[i][0] >= 0]
    for a, b in itertools.pairwise(full):  # overlapping recordings are merged message by message by rosbags
        if spans[a][1] >= spans[b][0]:
            return None
    return [recordings[i] for i in order]


def _span(files: list[_File]) -> tuple[int, int]:
    firsts = [f.first for f in files if f.first is not None]
    lasts = [f.last for f in files if f.last is not None]
    return (min(firsts), max(lasts)) if firsts else (-1, -2)


def _connect(path: str) -> Any:
    """A read-only, immutable connection to a .db3 file: through its write-ahead log when it has one with committed
    pages (a recording that was not closed: :mod:`wmrid.io.bag.db3_wal`)."""
    import apsw  # apsw: only a .db3 file's own reader

    view, _ = wal_state(path)  # an unreadable log is said in a note (Db3State)
    if view is not None:
        return connect(path, view)
    uri = "file:" + urllib.request.pathname2url(os.path.abspath(path)) + "?immutable=1"
    return apsw.Connection(uri, flags=apsw.SQLITE_OPEN_READONLY | apsw.SQLITE_OPEN_URI)


def _describe(path: str) -> _File | None:
    """The topics and time span of one .db3 file; None when it is not a rosbag2 sqlite3 file of CDR messages."""
    try:
        db = _connect(path)
    except Exception:
        return None
    try:
        tables = {name for (name,) in db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        if not {"messages", "topics"} <= tables:
            return None
        rows = list(db.execute("SELECT id, name, type, serialization_format FROM topics ORDER BY id"))
        if any(fmt != "cdr" for *_, fmt in rows):
            return None
        definitions: dict[str, str] = {}
        if "message_definitions" in tables:
            for name, encoding, text in db.execute(
                "SELECT topic_type, encoding, encoded_message_definition FROM message_definitions ORDER BY id"
            ):
                if encoding == "ros2msg" and name not in definitions:
                    definitions[name] = text or ""
        # Two scalar subqueries: each is one look-up in rosbag2's timestamp index, where MIN and MAX in one SELECT
        # scan the whole index (28 ms of a 600,000-message file from the page cache, ~0.1 s from disk).
        ((first, last),) = db.execute(
            "SELECT (SELECT MIN(timestamp) FROM messages), (SELECT MAX(timestamp) FROM messages)"
        )
    except Exception:  # not a database, another schema: rosbags says what is wrong
        return None
    finally:
        db.close()
    for stamp in (first, last):  # text sorts after every number: MAX finds one anywhere in the table
        if stamp is not None and type(stamp) is not int:
            raise LogFormatError(
                f"{path}: the recording is damaged: its messages table holds a time stamp that is not an integer "
                f"({repr(stamp)[:60]}); check it (ros2 bag info) or record it again"
            )
    topics = [(int(i), str(name), str(kind), definitions.get(kind, "")) for i, name, kind, _ in rows]
    return _File(path, topics, None if first is None else int(first), None if last is None else int(last))


class Db3State(_BagState):
    """The messages of the .db3 files of one or more recordings (:func:`db3_files`), read into :class:`_BagState`'s
    channels (see the module)."""

    def __init__(self, paths: Sequence[str], recordings: list[list[_File]], **kwargs: Any):
        super().__init__(", ".join(paths), "ros2", **kwargs)
        self.paths = list(paths)
        self.files = [f for r in recordings for f in r]
        self._ids: list[dict[int, int]] = []  # per file: topic id -> channel (skipped topics left out)
        by_topic: dict[str, int] = {}
        for file in self.files:
            view, problem = wal_state(file.path)
            if view is not None or problem is not None:
                self.notes.append(problem or view.note(file.path))
            ids = {}
            for topic_id, name, kind, definition in file.topics:
                channel = by_topic.get(name)
                if channel is None:
                    channel = len(by_topic) + 1
                    by_topic[name] = channel
                    self.add_topic(_Topic(channel, name, kind, definition, "cdr", []))
                elif self.topics[channel].msgtype != kind:
                    self.notes.append(
                        f"topic {name}: a connection of type {kind} besides {self.topics[channel].msgtype}; its "
                        "messages were skipped"
                    )
                    continue
                ids[topic_id] = channel
            self._ids.append(ids)

    def steps(self) -> Generator[None, None, None]:
        """Read every file, pausing after each block of messages."""
        decoded = set(self.joint_channels())
        for file, ids in zip(self.files, self._ids, strict=True):
            try:
                yield from self._file(file, ids, decoded)
            except LogFormatError:
                raise
            except Exception as err:  # apsw's errors of a damaged file
                raise LogFormatError(
                    f"{file.path}: the recording is damaged: its sqlite3 storage stopped reading ({_one_line(err)}); "
                    "check it (ros2 bag info) or record it again"
                ) from err

    def _file(self, file: _File, ids: dict[int, int], decoded: set[int]) -> Generator[None, None, None]:
        wanted = sorted(t for t, c in ids.items() if c in decoded)
        listed = ",".join(map(str, wanted))
        # A row's bytes come with it only when they are small (``inline``); a larger one is fetched alone by its
        # rowid, and one beyond the budget never: octet_length(data) reads the blob's size, not its bytes.
        inline = max(64 << 10, self.budget // (4 * _ROWS))
        if self.wanted is not None:  # a second pass: the decoded topics only
            if not wanted:
                return
            query = (f"SELECT topic_id, timestamp, CASE WHEN octet_length(data) <= {inline} THEN data END, "
                     f"octet_length(data), rowid FROM messages WHERE topic_id IN ({listed}) "
                     "ORDER BY timestamp")  # fmt: skip
        else:  # every message counted, the bytes of the decoded topics only
            query = (f"SELECT topic_id, timestamp, CASE WHEN topic_id NOT IN ({listed}) THEN X'' "
                     f"WHEN octet_length(data) <= {inline} THEN data END, "
                     f"CASE WHEN topic_id IN ({listed}) THEN octet_length(data) ELSE 0 END, rowid "
                     "FROM messages ORDER BY timestamp")  # fmt: skip
        table = np.full(max(ids, default=0) + 2, -1, dtype=np.int64)  # topic id -> channel; -1: none
        for topic_id, channel in ids.items():
            table[topic_id] = channel
        db = _connect(file.path)
        try:
            topic_ids: list[int] = []
            stamps: list[int] = []
            datas: list[Any] = []
            held = 0  # bytes in datas: a block holds about a quarter of the budget at most, or one large message
            for columns, alone in self._pieces(db, db.execute(query), file, table):
                if alone and datas:
                    self._block(table, topic_ids, stamps, datas, decoded)
                    topic_ids, stamps, datas, held = [], [], [], 0
                    yield
                topic_ids.extend(columns[0])
                stamps.extend(columns[1])
                datas.extend(columns[2])
                held += sum(columns[3])
                del columns
                if alone or len(datas) >= BATCH or held >= self.budget // 4:
                    self._block(table, topic_ids, stamps, datas, decoded)
                    topic_ids, stamps, datas, held = [], [], [], 0
                    yield
            if datas:
                self._block(table, topic_ids, stamps, datas, decoded)
                yield
        finally:
            db.close()

    def _pieces(self, db: Any, cursor: Any, file: _File, table: np.ndarray) -> Iterator[tuple[tuple, bool]]:
        """The rows of ``cursor`` (topic id, stamp, data, size, rowid) as columns, a few hundred rows at a time
        (their tuples dropped at once, see _ROWS), and (``alone`` True) each row that sqlite did not hand out
        inline by itself, its bytes read from the blob into one buffer (a plain fetch holds them twice); a row
        larger than the memory budget is left out, unread, and said in a note (as an MCAP record of that size is)."""
        while rows := list(itertools.islice(cursor, _ROWS)):
            columns = tuple(zip(*rows, strict=True))
            del rows
            if None not in columns[2]:
                yield columns, False
                continue
            start = 0
            for i in [i for i, blob in enumerate(columns[2]) if blob is None]:
                if start < i:
                    yield tuple(c[start:i] for c in columns), False
                start = i + 1
                topic_id, stamp, _, size, rowid = (c[i] for c in columns)
                if size > self.budget:
                    if self.wanted is None:
                        channel = int(table[topic_id]) if 0 <= topic_id < len(table) - 1 else -1
                        on = f" on {self.topics[channel].topic}" if channel in self.topics else ""
                        self.notes.append(
                            f"{file.path}: a message of {describe(size)}{on} (stamp {stamp} ns), beyond the memory "
                            f"budget of {describe(self.budget)} (WMRID_MEMORY_BUDGET), was skipped unread"
                        )
                    continue
                blob = bytearray(size)
                with db.blob_open("main", "messages", "data", rowid, False) as handle:
                    handle.read_into(blob)
                yield ((topic_id,), (stamp,), (blob,), (size,), (rowid,)), True
            if start < len(columns[0]):
                yield tuple(c[start:] for c in columns), False

    def _block(
        self, table: np.ndarray, topic_ids: list[int], stamps: list[int], datas: list[bytes], decoded: set[int]
    ) -> None:
        """One block of rows: the decoded topics' messages to their channels, every topic counted."""
        ids = np.fromiter(topic_ids, dtype=np.int64, count=len(topic_ids))
        known = (ids >= 0) & (ids < len(table) - 1)
        channels = np.where(known, table[np.where(known, ids, len(table) - 1)], -1)
        times = np.fromiter(stamps, dtype=np.int64, count=len(stamps))
        lengths = np.fromiter(map(len, datas), dtype=np.int64, count=len(datas))
        buf = np.frombuffer(datas[0] if len(datas) == 1 else b"".join(datas), dtype=np.uint8)
        starts = np.cumsum(lengths) - lengths
        first = int(channels[0])
        single = first >= 0 and bool((channels == first).all())
        for channel in [first] if single else np.unique(channels[channels >= 0]).tolist():
            sel = slice(None) if single else channels == channel
            acc = self.channels[channel]
            if channel in decoded:
                self.decode(channel, buf, starts[sel], lengths[sel], times[sel])
            else:
                lo, hi = int(times[sel].min()), int(times[sel].max())
                acc.first_ns = lo if acc.first_ns is None else min(acc.first_ns, lo)
                acc.last_ns = hi if acc.last_ns is None else max(acc.last_ns, hi)
            acc.count += len(times) if single else int(np.count_nonzero(sel))
