"""Sources followed while they are written, each read by wmrid's own readers as it grows.

:func:`wmrid.io.live.sources.open_live` takes what ``wmrid live`` is given: ``-`` (standard input: CSV rows with a
header, JSON lines, or an MCAP stream), a CSV file being appended to, an MCAP file being written (chunked or not), or
a rosbag2 folder being recorded with MCAP storage (split into several files: each new file is picked up once the one
before has its footer).  :meth:`LiveSource.poll` hands out the new wheel samples; ``ended`` says why a source ended
by itself (the end of standard input, the MCAP footer, the recorder's metadata.yaml); :meth:`LiveSource.final_input`
gives what the final ``identify`` reads: the recording itself when it was read to its end, else a copy of exactly the
bytes read (standard input is spilled to a temporary file as it arrives; a file still being written is copied up to
its last whole line or record), so the final result is ``identify`` on the same messages.
"""

from __future__ import annotations

import os
import re
import shutil
import sys
import tempfile
import time
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

from wmrid.core.errors import LogFormatError, UsageError
from wmrid.core.wheel_log import WheelLog
from wmrid.io.live.decoders import McapDecoder, TableDecoder
from wmrid.io.live.feeds import READ_BYTES, FileFeed, PipeFeed
from wmrid.io.live.framing import CsvBatcher, JsonLines, LineFramer, McapFramer
from wmrid.io.mcap.records import MAGIC
from wmrid.io.ros.selection import TopicSelection
from wmrid.io.signals import SignalOptions
from wmrid.io.sources import STDIN_NAME, compression_of
from wmrid.runtime.limits import memory_budget
from wmrid.runtime.side_files import broken_link, not_regular

#: An MCAP batch is decoded once it holds this many messages (or the source pauses or ends): enough for split
#: topics to overlap, few enough for a refresh.
BATCH_MESSAGES = 200
#: A batch that does not decode (too few messages of one topic to align, say) is kept and retried with more, up to
#: this many messages; then its error is the source's.
RETRY_MESSAGES = 5000


@dataclass(frozen=True)
class ReaderSettings:
    """How the followed log is read (the same as :func:`wmrid.io.logs.open_log`'s arguments).

    columns : {canonical name: column} (CSV), a JSON topic's field paths, or ``KEY=TOPIC:PATH`` field paths;
    time_unit : of a CSV time column; selection : bag topics, joints, time source, alignment; signals, gear_ratio :
    what the speeds and efforts hold.
    """

    columns: Mapping[str, str] | None = None
    time_unit: str = "auto"
    selection: TopicSelection = field(default_factory=TopicSelection)
    signals: SignalOptions = field(default_factory=SignalOptions)
    gear_ratio: float | None = None


@dataclass(frozen=True)
class FinalInput:
    """What the final ``identify`` reads: ``path`` (a file or a folder), ``copied`` True when it is a copy of the bytes
    read (in a temporary folder the source removes on close), ``name`` the source as the user named it, ``what`` how a
    copy is described ("" for the default: the bytes read)."""

    path: str
    copied: bool
    name: str
    what: str = ""


class LiveSource(ABC):
    """A log followed as it is written.  ``name`` as the user gave it; ``bytes_read``; ``last_data`` the monotonic time
    new bytes last arrived; ``ended`` None while it may still grow, else why it ended by itself.  ``tables``: it may
    bring CSV rows (the table readers, pandas and pyarrow's CSV, are then loaded before the first message)."""

    tables = True

    def __init__(self, name: str) -> None:
        self.name = name
        self.ended: str | None = None
        self.last_data = time.monotonic()
        self.bytes_read = 0
        self.quiet_since: float | None = None
        self._tmp: str | None = None

    @abstractmethod
    def poll(self, timeout: float) -> list[WheelLog]:
        """The samples that arrived, waiting up to ``timeout`` s for new bytes (a file is polled, a pipe waited on)."""

    @abstractmethod
    def final_input(self, natural: bool) -> FinalInput:
        """What the final ``identify`` reads; ``natural``: the run ended by the source's end or ``--idle`` (else a stop:
        Ctrl-C, ``--until``, ``--until-std``), so a file read to its end may be read again by name."""

    def flush(self) -> list[WheelLog]:
        """The samples of data read but held for a larger batch (called before a refresh); none by default."""
        return []

    def take_events(self) -> list[str]:
        """Lines on what happened to the source since the last call (a connection lost or regained); none by default."""
        return []

    def tmpdir(self) -> str:
        if self._tmp is None:
            self._tmp = tempfile.mkdtemp(prefix="wmrid-live-")
        return self._tmp

    def keep(self, final: FinalInput) -> str | None:
        """Move a copy of what was received (``final.copied``) out of the temporary folder that :meth:`close` removes,
        into the system's temporary folder under a name of its own; its new path (None when ``final`` is the source
        itself, which stays where it is).  For a final identify that failed: the messages are not lost with it."""
        if not final.copied or not os.path.exists(final.path):
            return None
        stamp = time.strftime("%Y%m%d-%H%M%S")
        suffix = "".join(Path(final.path).suffixes)
        kept = os.path.join(tempfile.gettempdir(), f"wmrid-live-received-{stamp}-{os.getpid()}{suffix}")
        shutil.move(final.path, kept)
        return kept

    def close(self) -> None:
        """Release the source and remove its temporary files."""
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None

    def _got(self, data: bytes) -> None:
        """Count ``data``, the bytes one read brought (b"" when it found none)."""
        if data:
            self.bytes_read += len(data)
            self.last_data = time.monotonic()
            self.quiet_since = None
        elif self.quiet_since is None:
            self.quiet_since = time.monotonic()

    def quiet(self) -> float:
        """s since a read first found no new bytes (0 while bytes keep coming): what ``--idle`` is compared with."""
        return 0.0 if self.quiet_since is None else time.monotonic() - self.quiet_since


def _copy_prefix(src: str, dst: str, size: int) -> None:
    """The first ``size`` bytes of ``src`` into a new file ``dst`` (in 1 MiB pieces: bounded memory)."""
    with open(src, "rb") as fin, open(dst, "wb") as fout:
        left = size
        while left > 0:
            block = fin.read(min(left, 1 << 20))
            if not block:
                break
            fout.write(block)
            left -= len(block)


class _Table:
    """CSV lines (or JSON lines turned into them) to samples: the batcher and the decoder, shared by sources."""

    def __init__(self, name: str, settings: ReaderSettings) -> None:
        self.batcher = CsvBatcher(name)
        self.decoder = TableDecoder(name, settings.columns, settings.time_unit, settings.signals, settings.gear_ratio)

    def samples(self, lines: bytes) -> list[WheelLog]:
        self.batcher.push(lines)
        batch = self.batcher.take()
        if batch is None:
            return []
        piece = self.decoder.decode(*batch)
        return [] if piece is None else [piece]


class _Mcap:
    """MCAP bytes to samples: the framer and the decoder (one decoder for the split files of a recording)."""

    def __init__(self, name: str, decoder: McapDecoder) -> None:

        self.decoder = decoder
        self.framer = McapFramer(name, decoder.keep, memory_budget())
        self.waiting = 0  # kept messages read and not yet decoded

    def samples(self, data: bytes, flush: bool) -> list[WheelLog]:
        before = self.framer.message_count
        self.framer.push(data)
        self.waiting += self.framer.message_count - before
        if self.waiting == 0 or (self.waiting < BATCH_MESSAGES and not flush and not self.framer.finished):
            return []
        messages = list(self.framer.messages)
        batch = self.framer.take()
        try:
            piece = self.decoder.decode(batch)
        except (LogFormatError, UsageError):
            if self.waiting >= RETRY_MESSAGES or flush or self.framer.finished:
                raise
            self.framer.messages = messages + self.framer.messages  # retried with more messages
            return []
        self.waiting = 0
        return [] if piece is None else [piece]


class StdinSource(LiveSource):
    """Standard input (or any pipe's file descriptor ``fd``): CSV rows with a header, JSON lines, or an MCAP stream,
    told apart by the first bytes.  Everything read is spilled to a temporary file as it arrives (JSON lines as
    the CSV they were turned into): the final ``identify`` reads that file."""

    def __init__(self, settings: ReaderSettings, stream: BinaryIO | None = None) -> None:
        super().__init__(STDIN_NAME)
        self.settings = settings
        if stream is None:
            if sys.stdin is None or sys.stdin.isatty():
                raise UsageError("source '-' means standard input, but nothing is piped in; give a file or pipe one in")
            stream = getattr(sys.stdin, "buffer", sys.stdin)
        self.feed = PipeFeed(stream)
        self.kind: str | None = None  # "csv", "json" or "mcap"
        self.head = b""
        self.spill_path: str | None = None
        self.spill = None
        self.lines: LineFramer | None = None
        self.json: JsonLines | None = None
        self.table: _Table | None = None
        self.mcap: _Mcap | None = None

    def _start(self) -> None:
        head = self.head.lstrip()
        if self.head.startswith(MAGIC[:1]):
            self.kind = "mcap"
        elif compression_of(self.head[:8]) is not None:
            raise LogFormatError(
                f"{STDIN_NAME}: a compressed stream cannot be followed as it arrives; pipe the decompressed rows "
                "(e.g. zcat run.csv.gz | wmrid live -)"
            )
        elif head.startswith(b"PAR1"):
            raise LogFormatError(
                f"{STDIN_NAME}: a Parquet file cannot be followed as it arrives; give it to wmrid identify"
            )
        else:
            self.kind = "json" if head.startswith(b"{") else "csv"
        suffix = ".mcap" if self.kind == "mcap" else ".csv"
        self.spill_path = os.path.join(self.tmpdir(), "stdin" + suffix)
        self.spill = open(self.spill_path, "wb")  # noqa: SIM115 - closed by close()
        if self.kind == "mcap":
            s = self.settings
            decoder = McapDecoder(STDIN_NAME, s.columns, s.selection, s.signals, s.gear_ratio)
            self.mcap = _Mcap(STDIN_NAME, decoder)
        else:
            self.lines = LineFramer(STDIN_NAME)
            self.table = _Table(STDIN_NAME, self.settings)
            if self.kind == "json":
                self.json = JsonLines(STDIN_NAME)

    def poll(self, timeout: float) -> list[WheelLog]:
        data = self.feed.read(timeout)
        self._got(data)
        if self.kind is None:
            self.head += data
            if len(self.head.lstrip()) < 8 and not self.feed.ended:
                return []
            if not self.head.strip():
                if self.feed.ended:
                    raise LogFormatError(
                        f"{STDIN_NAME}: standard input is empty; pipe CSV rows, JSON lines or an MCAP into it"
                    )
                return []
            self._start()
            data, self.head = self.head, b""
        out = self._take(data)
        if self.feed.ended and self.ended is None:
            self.ended = "the end of standard input"
        return out

    def _take(self, data: bytes) -> list[WheelLog]:
        end = self.feed.ended
        if self.kind == "mcap":
            self.spill.write(data)
            return self.mcap.samples(data, flush=end)
        lines = self.lines.push(data) + (self.lines.flush() if end else b"")
        if self.kind == "json":
            lines = self.json.convert(lines)
        self.spill.write(lines)
        return self.table.samples(lines)

    def final_input(self, natural: bool) -> FinalInput:
        if self.spill is None:
            raise LogFormatError(
                f"{STDIN_NAME}: nothing arrived on standard input; pipe CSV rows, JSON lines or an MCAP"
            )
        self.spill.flush()
        if self.kind == "mcap":  # up to the last whole record
            self.spill.truncate(self.mcap.framer.consumed)
            self.spill.flush()
        return FinalInput(self.spill_path, True, STDIN_NAME)

    def close(self) -> None:
        if self.spill is not None:
            self.spill.close()
            self.spill = None
        super().close()


class CsvFileSource(LiveSource):
    """A CSV file being appended to: its whole lines, read from where the last read stopped."""

    def __init__(self, path: str, settings: ReaderSettings) -> None:
        super().__init__(path)
        self.feed = FileFeed(path)
        self.lines = LineFramer(path)
        self.table = _Table(path, settings)

    def poll(self, timeout: float) -> list[WheelLog]:
        data = self.feed.read()
        self._got(data)
        if not data:
            time.sleep(timeout)
            return []
        return self.table.samples(self.lines.push(data))

    def final_input(self, natural: bool) -> FinalInput:
        if natural and self.feed.size() == self.lines.consumed:
            return FinalInput(self.name, False, self.name)
        copy = os.path.join(self.tmpdir(), os.path.basename(self.name))
        _copy_prefix(self.name, copy, self.lines.consumed)
        return FinalInput(copy, True, self.name)

    def close(self) -> None:
        self.feed.close()
        super().close()


class McapFileSource(LiveSource):
    """An MCAP file being written (chunked or not): its whole records; it ends at its footer."""

    tables = False

    def __init__(self, path: str, settings: ReaderSettings) -> None:
        super().__init__(path)
        s = settings
        self.feed = FileFeed(path)
        self.mcap = _Mcap(path, McapDecoder(path, s.columns, s.selection, s.signals, s.gear_ratio))

    def poll(self, timeout: float) -> list[WheelLog]:
        data = self.feed.read()
        self._got(data)
        if not data and self.mcap.waiting == 0:
            time.sleep(timeout)
            return []
        out = self.mcap.samples(data, flush=not data)
        if self.mcap.framer.finished:
            self.ended = "the recording's footer (the recorder closed the file)"
        return out

    def final_input(self, natural: bool) -> FinalInput:
        framer = self.mcap.framer
        if framer.finished or (natural and self.feed.size() == framer.consumed):
            return FinalInput(self.name, False, self.name)
        copy = os.path.join(self.tmpdir(), os.path.basename(self.name))
        _copy_prefix(self.name, copy, framer.consumed)
        return FinalInput(copy, True, self.name)

    def close(self) -> None:
        self.feed.close()
        super().close()


_SPLIT = re.compile(r"_(\d+)\.mcap$", re.IGNORECASE)


def _split_order(name: str) -> tuple[int, str]:
    match = _SPLIT.search(name)
    return (int(match.group(1)) if match else -1, name)


class Rosbag2Source(LiveSource):
    """A rosbag2 folder that ``ros2 bag record -s mcap`` is writing: its MCAP files in split order (NAME_0.mcap,
    NAME_1.mcap, ...), each followed to its footer before the next is opened; it ends once the recorder writes
    metadata.yaml and every file is read."""

    tables = False

    def __init__(self, folder: str, settings: ReaderSettings) -> None:
        super().__init__(folder)
        s = settings
        self.folder = folder
        self.decoder = McapDecoder(folder, s.columns, s.selection, s.signals, s.gear_ratio)
        self.done: list[str] = []  # files read to their footer
        self.current: str | None = None
        self.feed: FileFeed | None = None
        self.mcap: _Mcap | None = None
        self._refuse_other_storage()

    def _refuse_other_storage(self) -> None:
        names = os.listdir(self.folder)
        if any(n.lower().endswith((".db3", ".bag")) for n in names):
            raise UsageError(
                f"{self.folder}: a recording with sqlite3 (.db3) or ROS 1 storage; wmrid live follows MCAP storage "
                "(ros2 bag record -s mcap); identify this one with wmrid identify once it is finished"
            )

    def _files(self) -> list[str]:
        names = [n for n in os.listdir(self.folder) if n.lower().endswith(".mcap")]
        return [os.path.join(self.folder, n) for n in sorted(names, key=_split_order)]

    def _metadata(self) -> bool:
        return os.path.isfile(os.path.join(self.folder, "metadata.yaml"))

    def _refuse_odd(self, path: str) -> None:
        """LogFormatError, before it is opened, when the folder's ``path`` (named NAME.mcap, a file the user did not
        name) is not a regular file: a FIFO (opening it waited forever), a device, a loop of links or a link to
        nothing (an "internal error" on opening)."""
        kind = not_regular(path) or broken_link(path)
        if kind is not None:
            raise LogFormatError(
                f"{path}: it is {kind}, not a regular file, so wmrid does not open it (a file of the recording "
                f"{self.folder} by its name); remove it from the folder, or follow the recording's MCAP file itself"
            )

    def poll(self, timeout: float) -> list[WheelLog]:
        if self.current is None:
            pending = [f for f in self._files() if f not in self.done]
            if not pending:
                self._got(b"")
                if self._metadata():
                    self.ended = "the recorder's metadata.yaml (the recording is finished)"
                else:
                    time.sleep(timeout)
                return []
            self.current = pending[0]
            self._refuse_odd(self.current)
            self.feed = FileFeed(self.current)
            self.mcap = _Mcap(self.current, self.decoder)
        data = self.feed.read()
        self._got(data)
        if not data and self.mcap.waiting == 0 and not self.mcap.framer.finished:
            if self._metadata() and self.feed.size() == self.mcap.framer.consumed:
                self.ended = "the recorder's metadata.yaml (the recording is finished)"
                return []
            time.sleep(timeout)
            return []
        out = self.mcap.samples(data, flush=not data)
        if self.mcap.framer.finished:
            self.done.append(self.current)
            self.feed.close()
            self.current = None
        return out

    def final_input(self, natural: bool) -> FinalInput:
        if self.ended is not None and self._metadata():
            return FinalInput(self.folder, False, self.folder)
        copy = os.path.join(self.tmpdir(), os.path.basename(os.path.normpath(self.folder)))
        os.makedirs(copy, exist_ok=True)
        for f in self.done:
            shutil.copyfile(f, os.path.join(copy, os.path.basename(f)))
        if self.current is not None and self.mcap is not None and self.mcap.framer.consumed > 0:
            _copy_prefix(self.current, os.path.join(copy, os.path.basename(self.current)), self.mcap.framer.consumed)
        return FinalInput(copy, True, self.folder)

    def close(self) -> None:
        if self.feed is not None:
            self.feed.close()
        super().close()


__all__ = [
    "READ_BYTES",
    "CsvFileSource",
    "FinalInput",
    "LiveSource",
    "McapFileSource",
    "ReaderSettings",
    "Rosbag2Source",
    "StdinSource",
]
