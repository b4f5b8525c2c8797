"""ROS 1 bags, ROS 2 sqlite3 bags, rosbag2 folders and split recordings, read through rosbags into the contents an MCAP
read gives (:class:`wmrid.io.mcap.contents.McapContents`), so that topic, joint and time choices are the same for
every format.

rosbags opens the files (``rosbags.rosbag1.Reader`` for a ROS 1 bag, ``rosbags.rosbag2.Reader`` for a ``.db3`` or
``.mcap`` file or a rosbag2 folder with its ``metadata.yaml``) and hands out each message's serialised bytes with
its receive time; several files are merged in time order (``heapq.merge``, as rosbags' AnyReader does).  ROS 1 bags
(:mod:`wmrid.io.bag.ros1_file`), uncompressed sqlite3 storage (:mod:`wmrid.io.bag.db3_file`) and MCAP files
(:mod:`wmrid.io.bag.mcap_files`) are read by wmrid itself, which skips rosbags' per-message generators and reads a
file cut short by a crash; this module keeps what rosbags reads (compressed recordings, files that overlap in
time).  The JointState messages are gathered per topic in batches of
:data:`BATCH` and decoded by the compiled kernels of
:class:`wmrid.io.mcap.joint_batches.JointChannels`: :func:`wmrid.io.bag.ros1_records.ros1_joint_states` for ROS 1,
:func:`wmrid.io.mcap.records.joint_states` for CDR.  A message the kernel refuses, or a topic whose message
definition is not the standard JointState, is decoded by rosbags' deserialiser with the definitions stored in the
bag (a bag without them: the ROS 1 Noetic or ROS 2 Humble definitions).

A topic recorded over several connections (ROS 1 bags keep one per publisher, a split recording one per file) is
one channel.  Only JointState topics are read; the others are listed with their message count.
"""

from __future__ import annotations

import contextlib
import heapq
import os
from collections.abc import Callable, Generator, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path, PurePath
from typing import Any

import numpy as np

from wmrid.core.errors import LogFormatError
from wmrid.io.mcap.contents import Accumulator, McapContents
from wmrid.io.mcap.joint_batches import DYNAMIC_JOINT_STATE_NAMES, JointChannels
from wmrid.io.mcap.records import JOINT_STATE_NAMES, joint_states, ros1_joint_names, standard_joint_state

#: Messages per topic decoded at a time (the batch's bytes are joined into one buffer for the kernel).
BATCH = 16384


@dataclass
class _Topic:
    """One topic of the recording: the connections that carry it, its type and its message definition."""

    channel: int
    topic: str
    msgtype: str
    definition: str  # the .msg text ("" when the bag has none)
    encoding: str  # "ros1" or "cdr"
    connections: list[Any]


class BagFiles:
    """The files of one recording opened with rosbags: ``topics`` (channel id -> :class:`_Topic`), ``kind``
    ("ros1" or "ros2"), and :meth:`messages`.  Use as a context manager."""

    def __init__(self, paths: Sequence[str], kind: str):
        from rosbags.rosbag1 import Reader as Reader1
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


class _BagState(JointChannels):
    """The JointState decoding of :class:`JointChannels` for a bag's topics (``topics``: channel id ->
    :class:`_Topic`, added with :meth:`add_topic`); ``kind`` "ros1" or "ros2"."""

    def __init__(self, name: str, kind: str, **kwargs: Any):
        super().__init__(name, **kwargs)
        self.kind = kind
        self.topics: dict[int, _Topic] = {}
        self.typestore: Any = None

    def __enter__(self) -> _BagState:  # wmrid's own readers hold nothing open between steps
        return self

    def __exit__(self, *exc: object) -> None:
        pass

    def add_topic(self, topic: _Topic, count: int = 0) -> None:
        channel = topic.channel
        self.topics[channel] = topic
        encoding = "ros1msg" if topic.encoding == "ros1" else "ros2msg"
        self.schemas[channel] = {"name": topic.msgtype, "encoding": encoding, "data": topic.definition.encode()}
        self.channels[channel] = Accumulator(
            info={
                "id": channel, "topic": topic.topic, "message_encoding": topic.encoding, "schema_id": channel,
                "schema_name": topic.msgtype, "schema_encoding": encoding,
            }
        )  # fmt: skip
        self.channels[channel].count = count
        self.typestore = None  # rebuilt with this topic's definition when needed

    # ---- the format's JointState decoding

    def generic(self, acc: Accumulator, payload: bytes) -> Any:
        topic = self.topics[acc.info["id"]]
        try:
            store = self._types()
            if topic.encoding == "ros1":
                return store.deserialize_ros1(payload, topic.msgtype)
            return store.deserialize_cdr(payload, topic.msgtype)
        except Exception:
            return None

    def names_of(self, acc: Accumulator, payload: bytes) -> list[str] | None:
        """A ROS 1 JointState's names read straight from its bytes (no deserialiser needed for the common case);
        anything else as :class:`JointChannels` does."""
        topic = self.topics[acc.info["id"]]
        if topic.encoding == "ros1" and topic.msgtype in JOINT_STATE_NAMES and self.standard(acc):
            names = ros1_joint_names(payload)
            if names is not None:
                return names
        return super().names_of(acc, payload)

    def standard(self, acc: Accumulator) -> bool:
        topic = self.topics[acc.info["id"]]
        if not topic.definition:  # no definition in the bag: the standard one is assumed, as rosbags does
            return True
        return standard_joint_state("ros2msg", topic.definition.encode())  # the .msg syntax of ROS 1 and 2

    def kernel(self, acc: Accumulator) -> Callable[..., None]:
        if self.topics[acc.info["id"]].encoding == "ros1":
            from wmrid.io.bag.ros1_records import ros1_joint_states

            return ros1_joint_states
        return joint_states

    def _types(self) -> Any:
        """rosbags' typestore with the bag's definitions (the distribution's own where the bag has none)."""
        if self.typestore is None:
            from rosbags.typesys import Stores, get_types_from_msg, get_typestore

            store = get_typestore(Stores.ROS1_NOETIC if self.kind == "ros1" else Stores.ROS2_HUMBLE)
            for t in self.topics.values():  # one topic at a time: a definition that conflicts spoils only its own
                if t.definition:
                    try:
                        store.register(get_types_from_msg(t.definition, t.msgtype))
                    except Exception as err:
                        self.notes.append(
                            f"topic {t.topic}: its message definition cannot be used ({_one_line(err)}); its "
                            "messages are decoded with the distribution's definition where it has one"
                        )
            self.typestore = store
        return self.typestore

    def joint_channels(self) -> list[int]:
        channels = [
            c for c, t in self.topics.items()
            if t.msgtype in JOINT_STATE_NAMES + DYNAMIC_JOINT_STATE_NAMES or t.topic in self.fields
        ]  # fmt: skip
        return channels if self.wanted is None else [c for c in channels if c in self.wanted]

    def decode(self, channel: int, buf: np.ndarray, starts: np.ndarray, lengths: np.ndarray, stamps: np.ndarray):
        """A batch of one channel's messages: buf[starts[i] : starts[i] + lengths[i]] received at stamps[i] ns."""
        acc = self.channels[channel]
        lo, hi = int(stamps.min()), int(stamps.max())
        acc.first_ns = lo if acc.first_ns is None else min(acc.first_ns, lo)
        acc.last_ns = hi if acc.last_ns is None else max(acc.last_ns, hi)
        if acc.info["topic"] in self.fields:
            self._field_batch(acc, buf, starts, lengths, stamps)
        else:
            self._joint_batch(acc, buf, starts, lengths, stamps)


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


#: The rosbag2 metadata versions wmrid's own readers know (rosbags reads up to 9 too).
MAX_METADATA_VERSION = 9


#: bytes: the most a rosbag2 folder's metadata.yaml may hold (a real one is a few kilobytes: about 1 KB a topic and
#: 200 bytes a storage file).
METADATA_LIMIT = 4 << 20


def metadata_text(folder: str) -> bytes:
    """The bytes of the rosbag2 folder's ``metadata.yaml``, read by wmrid (the file is not one the user named):
    LogFormatError when it is not a regular file (a device such as /dev/zero, a FIFO, a link to either, a loop of
    links) or holds more than :data:`METADATA_LIMIT`, or when a storage file it lists is not a regular file
    (:func:`_check_listed_files`); ``b""`` when there is none or it cannot be read (rosbags then says why)."""
    from wmrid.core.side_files import NotRegularFile, broken_link, read_regular

    path = os.path.join(folder, "metadata.yaml")
    broken = broken_link(path)
    if broken is not None:
        raise LogFormatError(
            f"{path}: it is {broken}, so wmrid does not read it (the folder's metadata must be a file); fix the link, "
            "or give the recording's storage files (.db3, .mcap) instead"
        )
    try:
        message = (
            f"{_braces(path)}: a rosbag2 metadata.yaml over {{size}}; a real one is a few kilobytes: check the file, "
            "or give the recording's storage files (.db3, .mcap) instead of the folder"
        )
        text = read_regular(path, METADATA_LIMIT, message, LogFormatError)
    except NotRegularFile as err:
        raise LogFormatError(
            f"{path}: {err.strerror}, so wmrid does not read it (the folder's metadata must be a file); replace it "
            "with the recording's metadata.yaml, or give the recording's storage files (.db3, .mcap) instead"
        ) from err
    except OSError:
        return b""
    _check_listed_files(folder, text)
    return text


def _check_listed_files(folder: str, text: bytes) -> None:
    """Refuse (LogFormatError, before anything opens them) the storage files ``metadata.yaml`` lists that are not
    regular files: a FIFO (opening one waits for a writer, forever when none comes), a device (``/dev/zero`` never
    ends), a socket or folder, a loop of links (a missing file, or a link to nothing, the readers name).  The user
    named the folder, not these files.  Each is looked up by its name in the folder, as rosbags and wmrid's readers
    find it (a listed ``../x`` is ``x`` in the folder).  Metadata that cannot be parsed is left to the readers."""
    from wmrid.core.side_files import LOOP, broken_link, not_regular

    try:
        from ruamel.yaml import YAML

        listed = YAML(typ="safe").load(text.decode("utf-8"))["rosbag2_bagfile_information"]["relative_file_paths"]
        names = [PurePath(str(p)).name for p in listed]
    except Exception:  # not YAML, not rosbag2 metadata, no file list: the readers say so
        return
    for name in names:
        file = os.path.join(folder, name)
        kind = not_regular(file) or (LOOP if broken_link(file) == LOOP else None)  # one missing: the readers say
        if kind is not None:
            raise LogFormatError(
                f"{file}: it is {kind}, not a regular file, so wmrid does not open it (the folder's metadata.yaml "
                "lists it as a storage file of the recording); put the recording's file there, or give its storage "
                "files (.db3, .mcap) instead of the folder"
            )


def _braces(text: str) -> str:
    """``text`` safe inside a message that is formatted later (str.format)."""
    return text.replace("{", "{{").replace("}", "}}")


def storage_files(path: str, storage: str, magic: bytes) -> list[str] | None:
    """The storage files of one recording path when wmrid's own reader of ``storage`` ("sqlite3" or "mcap") takes
    it: a rosbag2 folder's by its metadata.yaml (that storage, uncompressed, every file present), or the path itself
    when it is a file starting with ``magic``; None otherwise (rosbags reads it, or says what is wrong)."""
    if not os.path.isdir(path):
        try:
            with open(path, "rb") as fh:
                return [path] if fh.read(len(magic)) == magic else None
        except OSError:
            return None
    text = metadata_text(path)  # refuses a device, a FIFO or an oversized file before rosbags reads it whole
    try:
        from ruamel.yaml import YAML

        info = YAML(typ="safe").load(text.decode("utf-8"))["rosbag2_bagfile_information"]
        if int(info["version"]) > MAX_METADATA_VERSION or info["storage_identifier"] != storage:
            return None
        if str(info.get("compression_mode") or "none").lower() != "none":
            return None
        files = [os.path.join(path, PurePath(str(p)).name) for p in info["relative_file_paths"]]
    except Exception:  # no or unreadable metadata, missing keys: rosbags says what is wrong
        return None
    for file in files:
        try:
            with open(file, "rb"):
                pass
        except FileNotFoundError:
            pass
        except OSError as err:  # no permission: said here, with the file's name (rosbags: "unable to open")
            raise LogFormatError(f"{file}: cannot be read ({err.strerror or err}); check its permissions") from None
    return files if files and all(os.path.isfile(f) for f in files) else None


def _unread_logs(paths: Sequence[str]) -> list[str]:
    """Notes for the .db3 files among ``paths`` (files or folders) whose write-ahead log holds committed messages
    that rosbags, which opens the database immutable, does not read."""
    from wmrid.io.bag.db3_wal import wal_state

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
        from wmrid.io.bag.ros1_file import Ros1State

        with Ros1State(paths, **kwargs) as state:
            yield state
        return
    from wmrid.io.bag.db3_file import Db3State, db3_files

    recordings = db3_files(paths)
    if recordings is not None:
        with Db3State(paths, recordings, **kwargs) as state:
            yield state
        return
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


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split())[:300] or type(err).__name__
