"""Frozen records that are JSON objects (:class:`JsonRecord`): one ``to_dict``/``from_dict`` for all of them, driven
by their dataclass fields, so that a record reads back exactly the object it was written as.

The rules, per field (its JSON key is its name):

* a field whose value is None is left out of the object, unless it is declared :func:`kept` (then ``null`` is
  written: a key the object always has, even when it has no value);
* :func:`nested` fields hold another record (an object in the JSON), :func:`each` fields a tuple of records (an array
  of objects), :func:`names` fields a tuple of plain values (an array);
* a :func:`spliced` field holds a record whose keys are written at its place in this object, not under a key of
  its own (the timing check's delay estimate, whose figures are the check's own keys);
* keys the record does not know (a newer wmrid's, or a method's own figures) are kept in ``other``, in their order,
  and written after the known ones;
* a ``null`` read for a field that is written only with a value is remembered in ``other`` too: the attribute reads
  None and the null is written back in the field's place (a value set later is written instead).

Each record's fields are declared in the order its keys are written.  A field's value is whatever the JSON holds
(numbers, strings, booleans, lists, objects), read as it is: a record does not check or convert it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

R = TypeVar("R", bound="JsonRecord")


def kept(**kwargs: Any) -> Any:
    """A field written even when it is None (``null``), default None."""
    return dataclasses.field(default=None, metadata={"keep": True}, **kwargs)


def nested(record: type[JsonRecord], keep: bool = False) -> Any:
    """A field holding a ``record`` (an object), default None."""
    return dataclasses.field(default=None, metadata={"record": record, "keep": keep})


def each(record: type[JsonRecord]) -> Any:
    """A field holding a tuple of ``record`` (an array of objects), default None."""
    return dataclasses.field(default=None, metadata={"each": record})


def names(keep: bool = False) -> Any:
    """A field holding a tuple of plain values (an array), default None."""
    return dataclasses.field(default=None, metadata={"seq": True, "keep": keep})


def spliced(record: type[JsonRecord]) -> Any:
    """A field holding a ``record`` whose keys are written in this object at this field's place, default None (when
    the object has none of them)."""
    return dataclasses.field(default=None, metadata={"splice": record})


def other_keys() -> Any:
    """The ``other`` field: the keys a record does not know, in their order."""
    return dataclasses.field(default_factory=dict, repr=False)


class JsonRecord:
    """Base of the frozen JSON records (a dataclass, ``kw_only``, with an ``other`` field last)."""

    other: dict[str, Any]

    def to_dict(self) -> dict[str, Any]:
        """The JSON object, keys in the fields' order, then ``other``'s."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            if f.name == "other":
                continue
            value = getattr(self, f.name)
            meta = f.metadata
            if "splice" in meta:
                if value is not None:
                    out.update(value.to_dict())
                continue
            if value is None:
                if meta.get("keep") or f.name in self.other:  # always written, or read as null: null in its place
                    out[f.name] = None
                continue
            if "record" in meta and isinstance(value, JsonRecord):
                value = value.to_dict()
            elif "each" in meta:
                value = [v.to_dict() if isinstance(v, JsonRecord) else v for v in value]
            elif meta.get("seq") and isinstance(value, tuple):
                value = list(value)
            out[f.name] = value
        for key, value in self.other.items():
            out.setdefault(key, value)  # a field set since it was read as null is written with its value
        return out

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        """The JSON keys this record knows (a spliced record's among them)."""
        out: list[str] = []
        for f in dataclasses.fields(cls):  # type: ignore[arg-type]
            if "splice" in f.metadata:
                out += f.metadata["splice"].keys()
            elif f.name != "other":
                out.append(f.name)
        return tuple(out)

    @classmethod
    def from_dict(cls: type[R], data: Mapping[str, Any]) -> R:
        """The record ``data`` (an object :meth:`to_dict` wrote, or an older or newer one) describes."""
        rest = dict(data)
        kwargs: dict[str, Any] = {}
        for f in dataclasses.fields(cls):  # type: ignore[arg-type]
            if f.name == "other":
                continue
            meta = f.metadata
            if "splice" in meta:
                part = {k: rest.pop(k) for k in meta["splice"].keys() if k in rest}  # noqa: SIM118 (a record's keys())
                if part:
                    kwargs[f.name] = meta["splice"].from_dict(part)
                continue
            if f.name not in rest:
                continue
            value = rest.pop(f.name)
            if value is None and not meta.get("keep"):
                rest[f.name] = None  # a null the object holds, for a field written only with a value: kept as such
                continue
            if "record" in meta and isinstance(value, Mapping):
                value = meta["record"].from_dict(value)
            elif "each" in meta and isinstance(value, list):
                value = tuple(meta["each"].from_dict(v) if isinstance(v, Mapping) else v for v in value)
            elif meta.get("seq") and isinstance(value, list):
                value = tuple(value)
            kwargs[f.name] = value
        make: Callable[..., R] = cls  # a dataclass's __init__, whose fields the base does not declare
        return make(**kwargs, other=rest)

    def merged(self: R, later: R | None) -> R:
        """This record with ``later``'s keys written over its own (``{**self, **later}`` of their objects)."""
        if later is None:
            return self
        return type(self).from_dict({**self.to_dict(), **later.to_dict()})
