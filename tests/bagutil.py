"""Real bags for the tests, written by rosbags' own writers (a helper module, not a test module).

:func:`recording` reads a ROS 2 MCAP recording's messages (rosbags' reader: topic, type, receive time, CDR bytes);
:func:`write_ros1` writes them to a ROS 1 bag (each JointState re-serialised for ROS 1 by rosbags, with a header
``seq``), :func:`write_rosbag2` to a rosbag2 folder (sqlite3 or MCAP storage, the CDR bytes as they are), and
:func:`write_split_rosbag2` to a rosbag2 folder split into several storage files, as ``ros2 bag record
--max-bag-size`` leaves it (one metadata.yaml listing every file).
"""

from __future__ import annotations

import functools
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

JOINT_STATE = "sensor_msgs/msg/JointState"


@dataclass(frozen=True)
class Message:
    topic: str
    msgtype: str
    log_ns: int
    cdr: bytes


def recording(path: Path) -> list[Message]:
    """Every message of a ROS 2 MCAP file, in file order."""
    from rosbags.highlevel import AnyReader

    with AnyReader([Path(path)]) as reader:
        return [Message(c.topic, c.msgtype, t, bytes(raw)) for c, t, raw in reader.messages()]


def _ros2_store():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def write_ros1(
    path: Path, messages: list[Message], compression: str | None = None, chunk_threshold: int | None = None
) -> Path:
    """A ROS 1 bag of the JointState messages (``compression``: None, "bz2" or "lz4" chunks; ``chunk_threshold``:
    bytes of records a chunk takes before the next begins, rosbags' 1 MiB by default)."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ros1 = get_typestore(Stores.ROS1_NOETIC)
    writer = Writer(Path(path))
    if chunk_threshold is not None:
        writer.chunk_threshold = chunk_threshold
    if compression is not None:
        writer.set_compression(getattr(Writer.CompressionFormat, compression.upper()))
    with writer:
        conns = {}
        for seq, m in enumerate(messages):
            if m.msgtype != JOINT_STATE:
                continue
            if m.topic not in conns:
                conns[m.topic] = writer.add_connection(m.topic, JOINT_STATE, typestore=ros1)
            writer.write(conns[m.topic], m.log_ns, _as_ros1(m.cdr, seq))
    return Path(path)


@functools.cache
def _ros1_and_ros2_stores():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC), _ros2_store()


@functools.lru_cache(maxsize=200_000)
def _as_ros1(cdr: bytes, seq: int) -> bytes:
    """A ROS 2 JointState (CDR) re-serialised for ROS 1 by rosbags, with header ``seq`` (remembered: the tests
    write the same recording as several ROS 1 bags)."""
    ros1, ros2 = _ros1_and_ros2_stores()
    js, header, time = (ros1.types[n] for n in (JOINT_STATE, "std_msgs/msg/Header", "builtin_interfaces/msg/Time"))
    msg = ros2.deserialize_cdr(cdr, JOINT_STATE)
    stamp = msg.header.stamp
    one = js(
        header=header(seq=seq, stamp=time(sec=stamp.sec, nanosec=stamp.nanosec), frame_id=msg.header.frame_id),
        name=list(msg.name), position=msg.position, velocity=msg.velocity, effort=msg.effort,
    )  # fmt: skip
    return bytes(ros1.serialize_ros1(one, JOINT_STATE))


def write_rosbag2(folder: Path, messages: list[Message], storage: str = "sqlite3", store=None) -> Path:
    """A rosbag2 folder (metadata.yaml and one storage file) of the messages, CDR bytes unchanged (``store``: the
    typestore that defines their types, ROS 2 Humble's by default)."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    store = store or _ros2_store()
    plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP
    with Writer(Path(folder), version=9, storage_plugin=plugin) as writer:
        conns = {}
        for m in messages:
            if m.topic not in conns:
                conns[m.topic] = writer.add_connection(m.topic, m.msgtype, typestore=store)
            writer.write(conns[m.topic], m.log_ns, m.cdr)
    return Path(folder)


def write_split_rosbag2(folder: Path, messages: list[Message], storage: str = "sqlite3", parts: int = 2) -> Path:
    """A rosbag2 folder whose messages are split over ``parts`` storage files in time order, one metadata.yaml
    listing them all (each part written by rosbags, then moved in and its file entry merged)."""
    from ruamel.yaml import YAML

    folder = Path(folder)
    cut = [round(i * len(messages) / parts) for i in range(parts + 1)]
    pieces = []
    for i in range(parts):
        piece = folder.parent / f"{folder.name}.part{i}"
        write_rosbag2(piece, messages[cut[i] : cut[i + 1]], storage)
        pieces.append(piece)
    yaml = YAML(typ="safe")
    meta = yaml.load((pieces[0] / "metadata.yaml").read_text())
    info = meta["rosbag2_bagfile_information"]
    folder.mkdir()
    info["relative_file_paths"], info["files"] = [], []
    counts: dict[str, int] = {}
    end = 0
    for i, piece in enumerate(pieces):
        part = yaml.load((piece / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        for rel, entry in zip(part["relative_file_paths"], part["files"], strict=True):
            name = f"{folder.name}_{i}{Path(rel).suffix}"
            shutil.move(str(piece / Path(rel).name), str(folder / name))
            info["relative_file_paths"].append(name)
            info["files"].append({**entry, "path": name})
        for topic in part["topics_with_message_count"]:
            counts[topic["topic_metadata"]["name"]] = (
                counts.get(topic["topic_metadata"]["name"], 0) + topic["message_count"]
            )
        end = max(end, part["starting_time"]["nanoseconds_since_epoch"] + part["duration"]["nanoseconds"])
        shutil.rmtree(piece)
    for topic in info["topics_with_message_count"]:
        topic["message_count"] = counts[topic["topic_metadata"]["name"]]
    info["message_count"] = sum(counts.values())
    info["duration"]["nanoseconds"] = end - info["starting_time"]["nanoseconds_since_epoch"]
    with open(folder / "metadata.yaml", "w") as fh:
        yaml.dump(meta, fh)
    return folder


DYNAMIC_JOINT_STATE = "control_msgs/msg/DynamicJointState"
DYNAMIC_JOINT_STATE_MSG = """std_msgs/Header header
string[] joint_names
InterfaceValue[] interface_values
================================================================================
MSG: control_msgs/InterfaceValue
string[] interface_names
float64[] values
"""


def dynamic_store():
    """rosbags' ROS 2 Humble typestore with control_msgs/DynamicJointState (not among its built-in types)."""
    from rosbags.typesys import get_types_from_msg

    store = _ros2_store()
    store.register(get_types_from_msg(DYNAMIC_JOINT_STATE_MSG, DYNAMIC_JOINT_STATE))
    return store


def as_dynamic(messages: list[Message], effort_interface: str = "effort") -> list[Message]:
    """The JointState messages as ros2_control's DynamicJointState on /dynamic_joint_states: per joint the
    interfaces position, velocity and ``effort_interface`` (e.g. "current"), in that order."""
    store = dynamic_store()
    dyn, value = store.types[DYNAMIC_JOINT_STATE], store.types["control_msgs/msg/InterfaceValue"]
    out = []
    for m in messages:
        if m.msgtype != JOINT_STATE:
            continue
        js = store.deserialize_cdr(m.cdr, JOINT_STATE)
        interfaces = [
            value(interface_names=["position", "velocity", effort_interface],
                  values=np.array([js.position[j], js.velocity[j], js.effort[j]]))
            for j in range(len(js.name))
        ]  # fmt: skip
        msg = dyn(header=js.header, joint_names=list(js.name), interface_values=interfaces)
        out.append(
            Message(
                "/dynamic_joint_states",
                DYNAMIC_JOINT_STATE,
                m.log_ns,
                bytes(store.serialize_cdr(msg, DYNAMIC_JOINT_STATE)),
            )
        )
    return out


MOTOR_STATE = "acme_msgs/msg/MotorState"
MOTOR_STATE_MSG = """std_msgs/Header header
MotorFeedback left
MotorFeedback right
================================================================================
MSG: acme_msgs/MotorFeedback
float64 current
float64 voltage
float64 temperature
"""


def motor_store(ros1: bool = False):
    """A typestore (ROS 2 Humble's, or ROS 1 Noetic's) with the vendor message acme_msgs/MotorState."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC) if ros1 else _ros2_store()
    store.register(get_types_from_msg(MOTOR_STATE_MSG, MOTOR_STATE))
    return store


def as_wheel_and_motor(messages: list[Message]) -> list[Message]:
    """The JointState messages split as a vendor base logs them: /wheel_state, a JointState with the speeds only,
    and /motor_state, acme_msgs/MotorState with each motor's current (= the effort here), voltage and temperature."""
    store = motor_store()
    js, state, feedback = (store.types[n] for n in (JOINT_STATE, MOTOR_STATE, "acme_msgs/msg/MotorFeedback"))
    out = []
    for m in messages:
        if m.msgtype != JOINT_STATE:
            continue
        msg = store.deserialize_cdr(m.cdr, JOINT_STATE)
        speeds = js(header=msg.header, name=list(msg.name), position=np.array([]), velocity=msg.velocity,
                    effort=np.array([]))  # fmt: skip
        side = {name: j for j, name in enumerate(msg.name)}
        motors = {
            s: feedback(current=float(msg.effort[side[f"{s}_wheel_joint"]]), voltage=12.0, temperature=40.0)
            for s in ("left", "right")
        }
        motor = state(header=msg.header, left=motors["left"], right=motors["right"])
        out.append(Message("/wheel_state", JOINT_STATE, m.log_ns, bytes(store.serialize_cdr(speeds, JOINT_STATE))))
        out.append(Message("/motor_state", MOTOR_STATE, m.log_ns, bytes(store.serialize_cdr(motor, MOTOR_STATE))))
    return out


def write_ros1_wheel_and_motor(path: Path, messages: list[Message]) -> Path:
    """:func:`as_wheel_and_motor`'s two topics in a ROS 1 bag (re-serialised for ROS 1, headers with ``seq``)."""
    from rosbags.rosbag1 import Writer

    ros1, ros2 = motor_store(ros1=True), motor_store()
    header, time = ros1.types["std_msgs/msg/Header"], ros1.types["builtin_interfaces/msg/Time"]
    js, state, feedback = (ros1.types[n] for n in (JOINT_STATE, MOTOR_STATE, "acme_msgs/msg/MotorFeedback"))
    with Writer(Path(path)) as writer:
        conns = {t: writer.add_connection(t, k, typestore=ros1) for t, k in (("/wheel_state", JOINT_STATE),
                                                                           ("/motor_state", MOTOR_STATE))}  # fmt: skip
        for seq, m in enumerate(messages):
            msg = ros2.deserialize_cdr(m.cdr, m.msgtype)
            head = header(seq=seq, stamp=time(sec=msg.header.stamp.sec, nanosec=msg.header.stamp.nanosec), frame_id="")
            if m.msgtype == JOINT_STATE:
                one = js(header=head, name=list(msg.name), position=msg.position, velocity=msg.velocity,
                         effort=msg.effort)  # fmt: skip
            else:
                one = state(header=head, **{s: feedback(current=getattr(msg, s).current, voltage=12.0,
                                                          temperature=40.0) for s in ("left", "right")})  # fmt: skip
            writer.write(conns[m.topic], m.log_ns, ros1.serialize_ros1(one, m.msgtype))
    return Path(path)
