"""The messages the compiled reader does not decode: any CDR message through mcap_ros2's generic decoder, and JSON
topics read with field paths (``--columns eta_r=wheels.right.velocity``)."""

from __future__ import annotations

import contextlib
import io
import json
from typing import Any

from wmrid.io.ros.contents import Accumulator


def decode_generic(state: Any, acc: Accumulator, payload: bytes) -> Any:
    """Decode one message with mcap_ros2's generic decoder (None if it cannot be decoded); the decoder of each
    channel is made once and kept in ``state.decoders`` (channel id -> decoder)."""
    cid = acc.info["id"]
    decoder = state.decoders.get(cid)
    if decoder is None:
        from mcap.records import Schema  # mcap's records (~20 ms): only a message the compiled reader does not decode

        # mcap_ros2's decoder (~25 ms): only a message the compiled reader does not decode
        from mcap_ros2.decoder import DecoderFactory

        s = state.schemas.get(acc.info["schema_id"])
        if s is None:
            return None
        schema = Schema(id=acc.info["schema_id"], name=s["name"], encoding=s["encoding"], data=s["data"])
        try:
            # mcap_ros2 prints parse problems of a damaged schema; keep them off wmrid's stdout/stderr.
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
                decoder = DecoderFactory().decoder_for("cdr", schema)
        except Exception as err:
            state.notes.append(f"topic {acc.info['topic']}: its schema cannot be parsed ({err}); skipped")
            return None
        if decoder is None:
            return None
        state.decoders[cid] = decoder
    try:
        return decoder(payload)
    except Exception:
        return None


def json_batch(state: Any, acc: Accumulator, buf: Any, starts: Any, lengths: Any, times: Any) -> None:
    """Numbers out of a batch of JSON messages on a topic read with field paths (``state.json_fields``)."""
    keys = state.json_fields[acc.info["topic"]]
    paths = [path.split(".") for path in keys.values()]
    for s, n, t in zip(starts, lengths, times, strict=True):
        try:
            obj = json.loads(bytes(buf[s : s + n]))
        except (ValueError, RecursionError):  # not JSON, or nested too deeply to be a message
            acc.skipped += 1
            continue
        acc.json_rows.append((int(t), [_lookup(obj, path) for path in paths]))


def _lookup(obj: Any, path: list[str]) -> float:
    """obj[path[0]][path[1]]... as a float (list indices as integers); NaN when absent or not a number."""
    for part in path:
        if isinstance(obj, list):
            try:
                obj = obj[int(part)]
            except (ValueError, IndexError):
                return float("nan")
        elif isinstance(obj, dict) and part in obj:
            obj = obj[part]
        else:
            return float("nan")
    if isinstance(obj, bool) or not isinstance(obj, (int, float)):
        return float("nan")
    return float(obj)
