"""Batches of a followed log to wheel samples, with wmrid's own readers.

:class:`TableDecoder`: CSV batches (:class:`wmrid.io.live.framing.CsvBatcher`) through the CSV reader
(:func:`wmrid.io.table.csv_log.csv_chunks`) and one assembler for the whole stream
(:class:`wmrid.io.assembler.Assembler`: the time unit, offset and epoch decisions are made once, on the first rows, and
every row is checked as it is in a file, time strictly increasing across batches included).

:class:`McapDecoder`: MCAP batches (:class:`wmrid.io.live.framing.McapFramer`) through the MCAP reader
(:func:`wmrid.io.mcap.reader.read_mcap`) and its signal rules (:func:`wmrid.io.ros.joints.signals_from_mcap`:
topics, joints, time source, split-topic alignment, speeds from positions, units; JSON topics and field paths), each
batch on its own; stamps stay integer nanoseconds until one offset for the whole stream turns them into seconds.
A batch's samples stamped at or before the last sample handed out are dropped (counted in ``dropped``).

Both hand out :class:`wmrid.core.wheel_log.WheelLog` pieces: t (k,) s, eta (k, 2) rad/s, tau (k, 2) in the effort
unit (N m unless the options say otherwise).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from wmrid.core.errors import UsageError, option
from wmrid.core.wheel_log import CANONICAL, REFERENCE, WheelLog
from wmrid.io.mcap.records import JOINT_STATE_NAMES
from wmrid.io.ros.field_paths import check_values, field_signals
from wmrid.io.ros.joint_batches import DYNAMIC_JOINT_STATE_NAMES
from wmrid.io.ros.joints import signals_from_json, signals_from_mcap
from wmrid.io.ros.selection import TopicSelection
from wmrid.io.signals import SignalOptions, convert
from wmrid.io.sources import Source
from wmrid.io.stamps import ABSOLUTE_LIMIT_S
from wmrid.io.table.columns import check_key

#: Rows asked of the CSV reader at once: a batch is read in one piece.
_ROWS = 1 << 30


class TableDecoder:
    """CSV batches (a prelude and data lines) to wheel samples, as :func:`wmrid.io.logs.open_log` reads a CSV file.

    columns : {canonical name: column} (``--columns``); time_unit : "auto", "s", "ms", "us" or "ns";
    signals, gear_ratio : what the speed and effort columns hold (:mod:`wmrid.io.signals`).
    """

    def __init__(
        self, name: str, columns: Mapping[str, str] | None, time_unit: str, signals: SignalOptions,
        gear_ratio: float | None,
    ) -> None:  # fmt: skip
        self.name = name
        self.mapping = {key: key for key in CANONICAL}
        for key, value in (columns or {}).items():
            check_key(key, "--columns")
            self.mapping[key] = value
        self.explicit = set(columns or ())
        self.time_unit = time_unit
        self.signals = signals
        self.gear_ratio = gear_ratio
        self.effort_unit = "N m" if signals == SignalOptions() else signals.effort_label
        self.assembler = None
        self.dropped = 0

    def decode(self, batch: bytes, rows_before: int) -> WheelLog | None:
        """The samples of one batch (``rows_before``: the data lines of the batches before it), or None."""
        from wmrid.io.assembler import MERGED_TIME, Assembler  # the assembler (~5 ms): only a CSV stream
        from wmrid.io.table.csv_log import csv_chunks  # the CSV reader (~10 ms): only a CSV stream

        source = Source(self.name, None, batch)
        chunks, where, _, hint = csv_chunks(source, self.mapping, self.explicit, _ROWS)

        def where_all(i: int) -> str:
            return where(i - rows_before)

        if self.assembler is None:
            self.assembler = Assembler(
                self.name, self.mapping, self.time_unit, hint, where_all, bool(self.explicit & set(REFERENCE)),
                merged=self.mapping["t"].lower() == MERGED_TIME,
            )  # fmt: skip
        self.assembler.where = where_all
        pieces = []
        for base, values in chunks():
            piece = self.assembler.add(values, rows_before + base)
            if piece is not None:
                pieces.append(piece)
        if not pieces:
            return None
        t = np.concatenate([p.t for p in pieces])
        eta = np.concatenate([p.eta for p in pieces])
        tau = np.concatenate([p.tau for p in pieces])
        if self.signals != SignalOptions():
            eta, tau, _ = convert(eta, tau, self.signals, self.gear_ratio)
        return WheelLog(t=t, eta=eta, tau=tau, source=self.name, effort_unit=self.effort_unit)


class McapDecoder:
    """MCAP batches to wheel samples, by the rules :func:`wmrid.io.mcap.log.read_mcap_log` reads a file with.

    columns : a JSON topic's {key: dotted field path} (with ``selection.topic``), or ``--columns KEY=TOPIC:PATH``
    field paths for any message type; selection : topics, joints, time source, alignment; signals, gear_ratio : as
    for :class:`TableDecoder`.
    """

    def __init__(
        self, name: str, columns: Mapping[str, str] | None, selection: TopicSelection, signals: SignalOptions,
        gear_ratio: float | None,
    ) -> None:  # fmt: skip
        from wmrid.io.mcap.log import field_selection  # the MCAP log's topic rules (~10 ms): only an MCAP stream

        self.name = name
        self.columns = dict(columns or {})
        self.fields = field_signals(self.columns) if self.columns else None
        self.json_topic = selection.topic if self.columns and self.fields is None else None
        if self.json_topic is None and self.columns and self.fields is None:
            raise UsageError(f"{name}: {option('columns')} with an MCAP needs {option('topic')} (a JSON topic) or "
                             "field paths KEY=TOPIC:PATH")  # fmt: skip
        self.selection = field_selection(selection, self.fields) if self.fields is not None else selection
        self.signals = signals
        self.gear_ratio = gear_ratio
        self.effort_unit = signals.effort_label
        self.offset: int | None = None  # ns subtracted from every stamp (epoch stamps), decided on the first batch
        self.started = False
        self.last_ns: int | None = None
        self.dropped = 0

    def keep(self, topic: str, schema: str) -> bool:
        """Whether a channel's messages can hold the wheel signals (the others are not kept)."""
        if self.fields is not None:
            return topic in self.fields.topics()
        if self.json_topic is not None:
            return topic == self.json_topic
        named = {self.selection.topic, self.selection.velocity_topic, self.selection.effort_topic} - {None}
        if named:
            return topic in named
        return schema in JOINT_STATE_NAMES + DYNAMIC_JOINT_STATE_NAMES

    def decode(self, batch: bytes) -> WheelLog | None:
        """The samples of one batch (a small MCAP file of its own), or None when it holds none past the last."""
        from wmrid.io.mcap.reader import read_mcap  # the MCAP reader (~15 ms): only an MCAP stream

        if self.fields is not None:
            contents = read_mcap(self.name, data=batch, fields=self.fields.topics())
            check_values(contents.joints, self.fields, self.name)
            sig = signals_from_mcap(contents, self.selection, self.signals, self.gear_ratio)
        elif self.json_topic is not None:
            contents = read_mcap(self.name, data=batch, json_fields={self.json_topic: self.columns})
            sig = signals_from_json(contents, self.json_topic, self.signals, self.gear_ratio)
        else:
            contents = read_mcap(self.name, data=batch)
            sig = signals_from_mcap(contents, self.selection, self.signals, self.gear_ratio)
        t_ns = np.asarray(sig.t_ns, dtype=np.int64)
        if self.last_ns is not None:
            new = t_ns > self.last_ns
            self.dropped += int(len(t_ns) - new.sum())
            t_ns, speed, effort = t_ns[new], sig.speed[new], sig.effort[new]
        else:
            speed, effort = sig.speed, sig.effort
        if len(t_ns) == 0:
            return None
        if not self.started:  # as wmrid.io.stamps.seconds_from_stamps decides for a whole file
            self.started = True
            largest = max(abs(int(t_ns[0])), abs(int(t_ns[-1])))
            self.offset = int(t_ns[0]) if largest >= ABSOLUTE_LIMIT_S * 1e9 else None
        self.last_ns = int(t_ns[-1])
        rel = t_ns - np.int64(self.offset) if self.offset is not None else t_ns
        t = rel.astype(np.float64) / 1e9
        eta = np.ascontiguousarray(speed, dtype=np.float64)
        tau = np.ascontiguousarray(effort, dtype=np.float64)
        return WheelLog(t=t, eta=eta, tau=tau, source=self.name, effort_unit=sig.effort_unit)
