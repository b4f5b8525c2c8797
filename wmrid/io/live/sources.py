"""What ``wmrid live`` is given, opened as the source it names (:func:`open_live`): the followed files and standard
input of :mod:`wmrid.io.live.follow`, or a Foxglove WebSocket server (:mod:`wmrid.io.live.ws_source`, imported only
for one: it loads ``websockets``)."""

from __future__ import annotations

import os

from wmrid.core.errors import LogFormatError, UsageError, option
from wmrid.io.live.follow import (
    CsvFileSource,
    LiveSource,
    McapFileSource,
    ReaderSettings,
    Rosbag2Source,
    StdinSource,
)
from wmrid.io.mcap.records import MAGIC
from wmrid.io.sources import compression_of
from wmrid.runtime.atomic import register_input


def open_live(spec: str, settings: ReaderSettings | None = None, reconnect: bool = False) -> LiveSource:
    """The source ``spec`` names: ``-`` (standard input), a CSV or MCAP file, a rosbag2 folder (MCAP storage), or a
    Foxglove WebSocket server ``ws://HOST:PORT`` (``reconnect``: retry when its connection is lost)."""
    settings = settings or ReaderSettings()
    if spec.startswith(("ws://", "wss://")):
        from wmrid.io.live.ws_source import WsSource  # start-up time: websockets only for a WebSocket source

        return WsSource(spec, settings, reconnect)
    if reconnect:
        raise UsageError(f"{spec}: {option('reconnect', True)} is for a WebSocket source (ws://HOST:PORT)")
    if spec == "-":
        return StdinSource(settings)
    if not os.path.exists(spec):
        raise LogFormatError(f"{spec}: no such file or folder; give the log being written (or - for standard input)")
    if os.path.isdir(spec):
        return Rosbag2Source(spec, settings)
    if not os.path.isfile(spec):
        raise LogFormatError(f"{spec}: not a regular file; give the log being written, or - for a pipe")
    register_input(spec)  # an output of this command may not be this file
    with open(spec, "rb") as fh:
        head = fh.read(8)
    if head.startswith(MAGIC[:1]) or (not head and spec.lower().endswith(".mcap")):
        return McapFileSource(spec, settings)
    if compression_of(head) is not None:
        raise LogFormatError(f"{spec}: a compressed file cannot be followed as it grows; give it to wmrid identify")
    if head.startswith(b"PAR1") or spec.lower().endswith((".parquet", ".pq")):
        raise LogFormatError(f"{spec}: a Parquet file cannot be followed as it grows; give it to wmrid identify")
    if head.lstrip().startswith(b"{"):
        raise LogFormatError(f"{spec}: JSON lines are followed on standard input only: tail -f {spec} | wmrid live -")
    return CsvFileSource(spec, settings)


__all__ = ["open_live"]
