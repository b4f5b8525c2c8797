"""Wheel signals taken from any message type by field path: ``TOPIC:PATH`` in ``--columns``.

``--columns eta_r=/wheel_state:velocity@right_wheel_joint,eta_l=/wheel_state:velocity@left_wheel_joint,
tau_r=/motor_state:right.current,tau_l=/motor_state:left.current`` reads the right wheel's speed from the array
``velocity`` of the messages on ``/wheel_state`` at the position of ``right_wheel_joint`` in their ``name`` array, and
its effort from the field ``current`` of the field ``right`` of the messages on ``/motor_state``.

PATH is fields separated by dots.  A field may be followed by ``[i]`` (element i of an array, from 0) or by
``@NAME`` (the element of an array at the position of NAME in the message's array of names beside it: the first
of ``name``, ``names``, ``joint_names`` and ``interface_names`` the message has; so
``interface_values@right_wheel_joint.values@velocity`` reads a ros2_control DynamicJointState).  A NAME holding a
dot or a comma is written in double quotes: ``velocity@"base.wheel_r"`` (``--columns`` splits at commas outside
quotes; the shell needs the whole option in single quotes then).  A field is looked up among the fields the
message's definition declares, never as a Python attribute (``__class__`` or numpy's ``size`` is no field): a step
naming no field, ``[i]`` on what is not an array, or a path ending at an array or a message is an error naming the
fields there are.  A value that is absent (a shorter array, a name not in the list) is NaN.  Both speeds come from
one topic, and both efforts from one topic (the same or another: the efforts are then aligned to the speeds'
stamps as for two JointState topics).
Time: each message's ``header.stamp`` when it has one, else its receive (log) time, as ``--time-source`` says.
The messages are decoded with the message definitions stored in the recording, message by message (about 20 µs
a message).  ``wmrid inspect`` lists the numeric field paths of every topic.
"""

from __future__ import annotations

import dataclasses
import math
import re
import weakref
from collections.abc import Mapping
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np

from wmrid.core.errors import LogFormatError, UsageError, option

#: Arrays of names an ``@NAME`` selector looks up, beside the array it selects from.
NAME_ARRAYS = ("name", "names", "joint_names", "interface_names")

_STEP = re.compile(r'^([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)\]|@"([^"]+)"|@([^"]+))?$')


@dataclass(frozen=True)
class FieldPath:
    """One ``TOPIC:PATH``: ``steps`` are (field, index or None, selector name or None)."""

    text: str
    topic: str
    steps: tuple[tuple[str, int | None, str | None], ...]

    def value(self, msg: Any) -> float:
        """The number at this path in a decoded message, NaN when absent (a shorter array, a name not in the
        list).  Each step is looked up among the fields its message declares (:func:`message_fields`), never as a
        Python attribute: a step that names no field of the message, an index or ``@NAME`` on what is not an array,
        or a path that ends at an array or a message raises :class:`FieldPathError` naming the path, the topic and
        the fields there are (the same for every message of a topic: they share one definition)."""
        obj = msg
        for k, (field, index, name) in enumerate(self.steps):
            parent = obj
            declared = message_fields(parent)
            if declared is None:
                raise FieldPathError(self, k, f"{_where(self, k)} is {_kind(parent)}, with no field {field!r}")
            if field not in declared:
                raise FieldPathError(
                    self, k, f"{_where(self, k)} has no field {field!r} (its fields: {', '.join(declared) or 'none'})"
                )
            obj = getattr(parent, field)
            if index is None and name is None:
                continue
            if not _is_array(obj):
                raise FieldPathError(self, k, f"{_where(self, k)}.{field} is {_kind(obj)}: it takes no [i] or @NAME")
            if index is not None:
                if index >= len(obj):
                    return math.nan
                obj = obj[index]
            else:
                names = next((getattr(parent, n) for n in NAME_ARRAYS if n in declared), None)
                if not _is_array(names):
                    raise FieldPathError(
                        self, k, f"{_where(self, k)} has no array of names ({', '.join(NAME_ARRAYS)}) for @{name}"
                    )
                try:
                    position = [str(n) for n in names].index(name)
                    obj = obj[position]
                except (IndexError, ValueError):
                    return math.nan
        if isinstance(obj, (bool, np.bool_)) or not isinstance(obj, (int, float, np.integer, np.floating)):
            hint = " (an element is [i] or @NAME)" if _is_array(obj) else ""
            end = len(self.steps)
            raise FieldPathError(self, end, f"{_where(self, end)} is {_kind(obj)}{hint}, not a number")
        return float(obj)


class FieldPathError(LogFormatError):
    """A field path that does not name a number of its topic's messages: a step that is no field of the message
    (a Python or numpy attribute such as ``__class__`` or ``size`` is none), ``[i]`` on what is not an array, a path
    ending at an array or a message.  Found while the log is read, so it is a LogFormatError: the readers let those
    through where they skip a damaged record."""

    def __init__(self, path: FieldPath, step: int, why: str):
        super().__init__(
            f"{option('columns')}: the field path {path.text} does not name a number of the messages on {path.topic}: "
            f"{why}; wmrid inspect lists the topic's numeric field paths"
        )


#: The declared fields of each message class whose fields are the class's (a dataclass, a namespace with
#: ``__slots__``), found once per class: every message of a topic is of one class, and a field path looks its fields up
#: at each step of each message (about a third of the time a message took).
#: Weakly: the readers make message classes per recording, which must not outlive it.
_CLASS_FIELDS: weakref.WeakKeyDictionary[type, tuple[str, ...]] = weakref.WeakKeyDictionary()


def message_fields(obj: Any) -> tuple[str, ...] | None:
    """The fields a decoded message declares in its definition (rosbags' dataclasses, mcap_ros2's namespaces with
    ``__slots__``), in order; None when ``obj`` is not a message (a number, a string, an array)."""
    cls = type(obj)
    known = _CLASS_FIELDS.get(cls)
    if known is not None:
        return known
    per_class = True
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        names = [f.name for f in dataclasses.fields(obj)]
    elif isinstance(obj, SimpleNamespace):
        slots = cls.__dict__.get("__slots__")
        per_class = isinstance(slots, (list, tuple))
        names = [str(s) for s in slots] if isinstance(slots, (list, tuple)) else list(vars(obj))
    else:
        return None
    # a ROS field name starts with a letter: rosbags' ``__msgtype__`` and the like are the library's, not the message's
    fields = tuple(n for n in names if n[:1].isalpha())
    if per_class:
        _CLASS_FIELDS[cls] = fields
    return fields


def _is_array(obj: Any) -> bool:
    return isinstance(obj, (list, tuple)) or (isinstance(obj, np.ndarray) and obj.ndim == 1)


def _kind(obj: Any) -> str:
    """What a value is, in the words of a message definition."""
    if message_fields(obj) is not None:
        return "a message"
    if _is_array(obj):
        return "an array"
    if isinstance(obj, (str, bytes)):
        return "a string"
    if isinstance(obj, (bool, np.bool_)):
        return "a bool"
    return "a number" if isinstance(obj, (int, float, np.integer, np.floating)) else "not a field value"


def _step_text(step: tuple[str, int | None, str | None]) -> str:
    field, index, name = step
    return field + (f"[{index}]" if index is not None else f"@{name}" if name is not None else "")


def _where(path: FieldPath, k: int) -> str:
    """The message at step k of a path, as the user wrote it: the topic's message, or ``TOPIC:a.b``."""
    return path.topic + ("" if k == 0 else ":" + ".".join(_step_text(s) for s in path.steps[:k]))


def is_field_path(text: str) -> bool:
    """Whether a ``--columns`` value is a ``TOPIC:PATH`` (a topic starts with '/')."""
    return text.startswith("/") and ":" in text


def parse(text: str) -> FieldPath:
    """A ``TOPIC:PATH``; UsageError naming the part that is not a field, ``[i]`` or ``@NAME``."""
    topic, _, path = text.partition(":")
    if not topic or not path:
        raise UsageError(
            f"{option('columns')}: {text!r} is not TOPIC:FIELD.PATH; write e.g. /motor_state:right.current"
        )
    steps = []
    for part in split_outside_quotes(path, "."):
        m = _STEP.match(part)
        if m is None:
            raise UsageError(
                f'{option("columns")}: {text!r}: {part!r} is not a field, field[i], field@NAME or field@"NAME"; '
                "write e.g. /wheel_state:velocity@right_wheel_joint"
            )
        field, index, quoted, name = m.groups()
        steps.append((field, None if index is None else int(index), quoted if quoted is not None else name))
    return FieldPath(text, topic, tuple(steps))


def split_outside_quotes(text: str, sep: str) -> list[str]:
    """``text`` split at each ``sep`` that is not between double quotes (the quotes are kept).  With an odd number
    of quotes none of them quotes: a lone ``"`` is part of a name (``--columns tau_r=cur"r`` as before quoting)."""
    parts, current, quoted = [], [], False
    for char in text:
        if char == '"':
            quoted = not quoted
        if char == sep and not quoted:
            parts.append("".join(current))
            current = []
        else:
            current.append(char)
    if quoted:
        return text.split(sep)
    parts.append("".join(current))
    return parts


@dataclass(frozen=True)
class FieldSignals:
    """The four wheel signals by field path: ``speed`` (right, left) on ``speed_topic``, ``effort`` on
    ``effort_topic``."""

    speed: tuple[FieldPath, FieldPath]
    effort: tuple[FieldPath, FieldPath]

    @property
    def speed_topic(self) -> str:
        return self.speed[0].topic

    @property
    def effort_topic(self) -> str:
        return self.effort[0].topic

    def topics(self) -> dict[str, dict[str, tuple[FieldPath, FieldPath]]]:
        """{topic: {"velocity": paths, "effort": paths}} of the topics to decode."""
        out: dict[str, dict[str, tuple[FieldPath, FieldPath]]] = {}
        out.setdefault(self.speed_topic, {})["velocity"] = self.speed
        out.setdefault(self.effort_topic, {})["effort"] = self.effort
        return out


def field_signals(columns: Mapping[str, str]) -> FieldSignals | None:
    """The field-path signals of a ``--columns`` mapping, None when it names none; UsageError when it mixes them
    with column names, leaves a signal out, or spreads the speeds (or the efforts) over two topics."""
    paths = {key: value for key, value in columns.items() if is_field_path(value)}
    if not paths:
        return None
    needed = ("eta_r", "eta_l", "tau_r", "tau_l")
    missing = [k for k in needed if k not in paths]
    extra = [k for k in columns if k not in needed]
    if missing or extra:
        raise UsageError(
            f"{option('columns')} with field paths (TOPIC:FIELD) needs exactly eta_r, eta_l, tau_r and tau_l as "
            f"paths{'; missing ' + ', '.join(missing) if missing else ''}"
            f"{'; not by path: ' + ', '.join(extra) if extra else ''} (time comes from the messages' stamps)"
        )
    parsed = {key: parse(paths[key]) for key in needed}
    for a, b, what in (("eta_r", "eta_l", "speeds"), ("tau_r", "tau_l", "efforts")):
        if parsed[a].topic != parsed[b].topic:
            raise UsageError(
                f"{option('columns')}: both {what} must come from one topic ({parsed[a].topic} and {parsed[b].topic} "
                "given)"
            )
    return FieldSignals((parsed["eta_r"], parsed["eta_l"]), (parsed["tau_r"], parsed["tau_l"]))


#: ROS base types that hold a number a wheel signal can be.
NUMERIC_TYPES = ("float64", "float32", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64")


def numeric_paths(fielddefs: Mapping[str, Any], typename: str, limit: int = 40) -> list[str]:
    """The numeric field paths of a message type (``header`` left out: it holds time, not a signal), as
    ``--columns`` takes them after ``TOPIC:``; an array beside an array of names shows ``@NAME``, another ``[i]``.

    fielddefs : rosbags' ``Typestore.fielddefs`` ({type: (constants, [(field, (node kind, detail))])}).
    """
    out: list[str] = []
    visits = [0]  # a cap on the fields looked at: nested definitions can branch without limit

    def walk(name: str, prefix: str, depth: int) -> None:
        visits[0] += 1
        if depth > 8 or name not in fielddefs or len(out) >= limit or visits[0] > 2000:
            return
        fields = fielddefs[name][1]
        here = {f for f, _ in fields}
        sibling = next((n for n in NAME_ARRAYS if n in here), None)
        for field, (node, detail) in fields:
            if field == "header" and depth == 0:
                continue
            path = f"{prefix}{field}"
            kind = getattr(node, "name", str(node))
            if kind in ("ARRAY", "SEQUENCE"):
                (sub_node, sub_detail), _ = detail
                path += "@NAME" if sibling and sibling != field else "[i]"
                node, detail, kind = sub_node, sub_detail, getattr(sub_node, "name", str(sub_node))
            if kind == "BASE" and detail[0] in NUMERIC_TYPES:
                out.append(path)
            elif kind == "NAME":
                walk(detail, path + ".", depth + 1)

    walk(typename, "", 0)
    return out[:limit]


def check_values(series_by_topic: Mapping[str, Any], fs: FieldSignals, source: str) -> None:
    """LogFormatError naming a field path that gave no number in any message of its topic (a misspelt field)."""
    for field, paths in (("velocity", fs.speed), ("effort", fs.effort)):
        series = series_by_topic.get(paths[0].topic)
        if series is None:
            raise LogFormatError(
                f"{source}: no messages on {paths[0].topic} (from {option('columns')} {paths[0].text}); wmrid inspect "
                "lists the topics"
            )
        for j, path in enumerate(paths):
            if not _has_values(series, field, j):
                raise LogFormatError(
                    f"{source}: the field path {path.text} gives no number in any message on {path.topic}; wmrid "
                    "inspect lists its numeric fields"
                )


def _has_values(series: Any, field: str, column: int) -> bool:
    if hasattr(series, "has_value"):  # a summary of a long recording
        return bool(series.has_value[("position", "velocity", "effort").index(field), column])
    values = getattr(series, field)
    return bool(values.shape[0]) and not bool(np.all(np.isnan(values[:, column])))
