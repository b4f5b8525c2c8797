"""What every bag reader shares (issue 31: the bag readers' shared state in a module of its own): the JointState
decoding of a bag's topics (:class:`_BagState`, on the compiled kernels of
:class:`wmrid.io.ros.joint_batches.JointChannels`), a topic's record (:class:`_Topic`), and the rosbag2 folder's
metadata (:func:`metadata_text`, :func:`storage_files`).  :mod:`wmrid.io.bag.reader` (rosbags' reads) and wmrid's
own readers of ROS 1 bags, sqlite3 and MCAP storage (:mod:`wmrid.io.bag.ros1_file`, :mod:`wmrid.io.bag.db3_file`,
:mod:`wmrid.io.bag.mcap_files`) build on it."""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import PurePath
from typing import Any

import numpy as np

from wmrid.core.errors import LogFormatError
from wmrid.io.binary import read_only
from wmrid.io.mcap.records import JOINT_STATE_NAMES, joint_states, ros1_joint_names, standard_joint_state
from wmrid.io.ros.contents import Accumulator
from wmrid.io.ros.joint_batches import DYNAMIC_JOINT_STATE_NAMES, JointChannels
from wmrid.runtime.side_files import LOOP, NotRegularFile, broken_link, not_regular, read_regular

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
            from wmrid.io.bag.ros1_records import ros1_joint_states  # the ROS 1 decoder: only a ROS 1 topic

            return ros1_joint_states
        return joint_states

    def _types(self) -> Any:
        """rosbags' typestore with the bag's definitions (the distribution's own where the bag has none)."""
        if self.typestore is None:
            # rosbags' type system (~15 ms): only a message the compiled decoders do not take
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
        buf = read_only(buf)  # one array type for the kernels, whatever held the bytes (a map, a chunk, a join)
        acc = self.channels[channel]
        lo, hi = int(stamps.min()), int(stamps.max())
        acc.first_ns = lo if acc.first_ns is None else min(acc.first_ns, lo)
        acc.last_ns = hi if acc.last_ns is None else max(acc.last_ns, hi)
        if acc.info["topic"] in self.fields:
            self._field_batch(acc, buf, starts, lengths, stamps)
        else:
            self._joint_batch(acc, buf, starts, lengths, stamps)


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
    try:
        from ruamel.yaml import YAML  # ruamel.yaml (~10 ms): only a rosbag2 folder's metadata.yaml

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
        from ruamel.yaml import YAML  # ruamel.yaml (~10 ms): only a rosbag2 folder's metadata.yaml

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


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split())[:300] or type(err).__name__
