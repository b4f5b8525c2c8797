"""ROS 1 bags, ROS 2 sqlite3 bags, rosbag2 folders and split recordings, read through rosbags into the contents an MCAP
read gives (:class:`wmrid.io.ros.contents.McapContents`), so that topic, joint and time choices are the same for
every format.

rosbags opens the files (``rosbags.rosbag1.Reader`` for a ROS 1 bag, ``rosbags.rosbag2.Reader`` for a ``.db3`` or
``.mcap`` file or a rosbag2 folder with its ``metadata.yaml``) and hands out each message's serialised bytes with
its receive time; several files are merged in time order (``heapq.merge``, as rosbags' AnyReader does).  ROS 1 bags
(:mod:`wmrid.io.bag.ros1_file`), uncompressed sqlite3 storage (:mod:`wmrid.io.bag.db3_file`) and MCAP files
(:mod:`wmrid.io.bag.mcap_files`) are read by wmrid itself, which skips rosbags' per-message generators and reads a
file cut short by a crash; this module keeps what rosbags reads (compressed recordings, files that overlap in
time).  The JointState messages are gathered per topic in batches of
:data:`wmrid.io.bag.state.BATCH` and decoded by the compiled kernels of
:class:`wmrid.io.ros.joint_batches.JointChannels`: :func:`wmrid.io.bag.ros1_records.ros1_joint_states` for ROS 1,
:func:`wmrid.io.mcap.records.joint_states` for CDR.  A message the kernel refuses, or a topic whose message
definition is not the standard JointState, is decoded by rosbags' deserialiser with the definitions stored in the
bag (a bag without them: the ROS 1 Noetic or ROS 2 Humble definitions).

A topic recorded over several connections (ROS 1 bags keep one per publisher, a split recording one per file) is
one channel.  Only JointState topics are read; the others are listed with their message count.
"""

from __future__ import annotations

import contextlib
import heapq
from collections.abc import Generator, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from wmrid.core.errors import LogFormatError
from wmrid.io.bag.state import (
    BATCH,
    _BagState,
    _one_line,
    _Topic,
    metadata_text,
)
from wmrid.io.ros.contents import McapContents


class BagFiles:
    """The files of one recording opened with rosbags: ``topics`` (channel id -> :class:`_Topic`), ``kind``
    ("ros1" or "ros2"), and :meth:`messages`.  Use as a context manager."""

    def __init__(self, paths: Sequence[str], kind: str):
        # rosbags' readers (~50 ms): only a recording wmrid's own readers do not take
        from rosbags.rosbag1 import Reader as Reader1

        # rosbags' readers (~50 ms): only a recording wmrid's own readers do not take
        from rosbags.rosbag2 import Reader as Reader2

        self.paths, self.kind = list(paths), kind
        self.readers = []
        for path in self.paths:
            try:  # rosbags looks at the files already here (a folder's storage files, their suffixes)
                self.readers.append((Reader1 if kind == "ros1" else Reader2)(Path(path)))
            except Exception as err:
                raise self._cannot_open(path, err) from err
        self.topics: dict[int, _Topic] = {}
        self.notes: list[str] = []
        self._by_connection: dict[int, int] = {}  # id(connection) -> channel id

    def __enter__(self) -> BagFiles:
        opened = []
        try:
            for path, reader in zip(self.paths, self.readers, strict=True):
                try:
                    reader.open()
                except Exception as err:
                    raise self._cannot_open(path, err) from err
                opened.append(reader)
        except BaseException:
            for reader in opened:
                reader.close()
            raise
        self._gather()
        return self

    def _cannot_open(self, path: str, err: Exception) -> LogFormatError:
        what = "a ROS 1 bag" if self.kind == "ros1" else "a ROS 2 recording"
        return LogFormatError(
            f"{path}: {what} that rosbags cannot open ({_one_line(err)}); check the recording (rosbag check, ros2 bag "
            "info) or record it again"
        )

    def __exit__(self, *exc: object) -> None:
        for reader in self.readers:
            reader.close()

    def _gather(self) -> None:
        by_topic: dict[str, _Topic] = {}
        for reader in self.readers:
            for conn in reader.connections:
                definition = conn.msgdef.data if conn.msgdef.format.name == "MSG" else ""
                known = by_topic.get(conn.topic)
                if known is None:
                    known = _Topic(len(by_topic) + 1, conn.topic, conn.msgtype, definition,
                                   "ros1" if self.kind == "ros1" else "cdr", [])  # fmt: skip
                    by_topic[conn.topic] = known
                    self.topics[known.channel] = known
                elif known.msgtype != conn.msgtype:
                    self.notes.append(
                        f"topic {conn.topic}: a connection of type {conn.msgtype} besides {known.msgtype}; its "
                        "messages were skipped"
                    )
                    continue
                known.connections.append(conn)
                self._by_connection[id(conn)] = known.channel

    def count(self, channel: int) -> int:
        return sum(int(c.msgcount) for c in self.topics[channel].connections)

    def batches(self, channels: Iterable[int]) -> Iterator[tuple[int, Sequence[int], Sequence[bytes]]]:
        """(channel id, receive times ns, serialised messages) of the channels' messages, in time order, up to
        :data:`BATCH` messages of one channel at a time."""
        wanted = set(channels)
        pending: dict[int, tuple[list[int], list[bytes]]] = {c: ([], []) for c in wanted}
        for channel, stamp, raw in self.messages(wanted):
            times, datas = pending[channel]
            times.append(stamp)
            datas.append(raw)
            if len(datas) >= BATCH:
                yield channel, times, datas
                pending[channel] = ([], [])
        for channel, (times, datas) in pending.items():
            if datas:
                yield channel, times, datas

    def messages(self, channels: Iterable[int]) -> Iterator[tuple[int, int, bytes]]:
        """(channel id, receive time ns, serialised bytes) of the channels' messages, in time order."""
        wanted = set(channels)
        streams = []
        for reader in self.readers:
            conns = [c for c in reader.connections if self._by_connection.get(id(c)) in wanted]
            if conns:
                streams.append(reader.messages(connections=conns))
        by_connection = self._by_connection
        try:
            for conn, stamp, raw in heapq.merge(*streams, key=lambda m: m[1]):
                yield by_connection[id(conn)], stamp, raw
        except LogFormatError:
            raise
        except Exception as err:  # rosbags, sqlite or struct errors of a damaged file
            raise LogFormatError(
                f"{', '.join(self.paths)}: the recording is damaged: rosbags stopped reading it ({_one_line(err)}); "
                "check it (ros2 bag info) or record it again"
            ) from err


class _RosbagsState(_BagState):
    """A recording read message by message through rosbags (:class:`BagFiles`): ROS 2 sqlite3 and MCAP storage."""

    def __init__(self, files: BagFiles, **kwargs: Any):
        super().__init__(", ".join(files.paths), files.kind, **kwargs)
        self.files = files
        for topic in files.topics.values():
            self.add_topic(topic, files.count(topic.channel))
        self.notes.extend(files.notes)
        self.notes.extend(_unread_logs(files.paths))

    def steps(self) -> Generator[None, None, None]:
        """Decode the JointState topics (``wanted`` of them when set), pausing after each batch."""
        for channel, times, datas in self.files.batches(self.joint_channels()):
            self._flush(channel, times, datas)
            yield

    def _flush(self, channel: int, times: Sequence[int], datas: Sequence[bytes]) -> None:
        lengths = np.fromiter(map(len, datas), dtype=np.int64, count=len(datas))
        starts = np.cumsum(lengths) - lengths
        self.decode(channel, np.frombuffer(b"".join(datas), dtype=np.uint8), starts, lengths,
                    np.asarray(times, dtype=np.int64))  # fmt: skip


def _unread_logs(paths: Sequence[str]) -> list[str]:
    """Notes for the .db3 files among ``paths`` (files or folders) whose write-ahead log holds committed messages
    that rosbags, which opens the database immutable, does not read."""
    from wmrid.io.bag.db3_wal import wal_state  # the write-ahead log's reader: only .db3 files

    found = []
    for path in map(Path, paths):
        for wal in sorted(path.glob("*.db3-wal")) if path.is_dir() else [Path(f"{path}-wal")]:
            db = str(wal)[: -len("-wal")]
            if any(wal_state(db)):  # committed pages, or unreadable (it may hold messages)
                found.append(
                    f"{db}: the recording was not closed and its write-ahead log ({wal.name}) holds committed "
                    "pages that may not be in the database yet; read through rosbags (a compressed recording, or "
                    "files that overlap in time), the messages in them are left out"
                )
    return found


def bag_kind(paths: Sequence[str]) -> str:
    """ "ros1" when every path is a ROS 1 bag (by its magic bytes), "ros2" when none is; a mixture is refused."""
    kinds = {_kind(p) for p in paths}
    if len(kinds) > 1:
        raise LogFormatError(
            f"{', '.join(paths)}: ROS 1 bags and ROS 2 recordings mixed; give the files of one recording"
        )
    return kinds.pop()


def _kind(path: str) -> str:
    if Path(path).is_dir():
        metadata_text(path)  # a metadata.yaml that is a device, a FIFO or oversized: refused before anything reads it
        return "ros2"
    with open(path, "rb") as fh:
        return "ros1" if fh.read(13).startswith(b"#ROSBAG V2.0") else "ros2"


def read_bag(
    paths: Sequence[str], *, keep: int | None = None, spare: int = 0, fields: Mapping[str, Any] | None = None
) -> McapContents:
    """The recording of ``paths`` (one or more ROS 1 bags, ``.db3``/``.mcap`` files, or a rosbag2 folder) as the
    contents of an MCAP read: channels, JointState series (or, past ``keep`` messages, summaries, and the parts
    kept within ``spare`` bytes: see :class:`JointChannels`), notes.  Raises LogFormatError when rosbags cannot
    open a file."""
    kind = bag_kind(paths)
    with _open_state(paths, kind, keep=keep, spare=spare, fields=fields) as state:
        for _ in state.steps():
            pass
        return McapContents(
            source=", ".join(paths), profile=kind, library="rosbags" if isinstance(state, _RosbagsState) else "wmrid",
            format=f"{kind} bag", channels=tuple(state.channel_info()),
            definitions={t.topic: (t.msgtype, t.definition) for t in state.topics.values()},
            joints=state.joints(), json={}, metadata={}, notes=tuple(state.notes), size_bytes=_size(paths),
            complete=state.complete, replay=None if state.complete else state.replay,
        )  # fmt: skip


def iter_bag_joint_parts(
    paths: Sequence[str], channel_ids: Iterable[int], fields: Mapping[str, Any] | None = None
) -> Generator[dict[int, list[tuple[np.ndarray, ...]]], None, None]:
    """The second pass over a recording read by :func:`read_bag`: the parts of the JointState channels
    ``channel_ids``, batch by batch (as :func:`wmrid.io.mcap.reader.iter_joint_parts`)."""
    wanted = set(channel_ids)
    with _open_state(paths, bag_kind(paths), wanted=wanted, fields=fields) as state:
        for _ in state.steps():
            out = {}
            for cid in wanted:
                acc = state.channels.get(cid)
                if acc is not None and acc.parts:
                    out[cid], acc.parts = acc.parts, []
            if out:
                yield out


@contextlib.contextmanager
def _open_state(paths: Sequence[str], kind: str, **kwargs: Any) -> Iterator[_BagState]:
    """The state that reads ``paths``: wmrid's own readers for ROS 1 bags, uncompressed sqlite3 recordings and MCAP
    files, rosbags for the other ROS 2 recordings (compressed, or files that overlap in time)."""
    if kind == "ros1":
        from wmrid.io.bag.ros1_file import Ros1State  # each storage's reader is loaded only for its recordings

        with Ros1State(paths, **kwargs) as state:
            yield state
        return
    from wmrid.io.bag.db3_file import Db3State, db3_files  # each storage's reader is loaded only for its recordings

    recordings = db3_files(paths)
    if recordings is not None:
        with Db3State(paths, recordings, **kwargs) as state:
            yield state
        return
    # each storage's reader is loaded only for its recordings
    from wmrid.io.bag.mcap_files import McapFilesState, mcap_files

    files = mcap_files(paths)
    if files is not None:
        with McapFilesState(paths, files, **kwargs) as state:
            yield state
        return
    with BagFiles(paths, kind) as files:
        yield _RosbagsState(files, **kwargs)


def _size(paths: Sequence[str]) -> int:
    total = 0
    for p in paths:
        path = Path(p)
        files = path.rglob("*") if path.is_dir() else [path]
        total += sum(f.stat().st_size for f in files if f.is_file())
    return total
