"""The final ``identify`` of a live run (:meth:`wmrid.api.live.LiveRun.finish`): run lean on memory past
:data:`wmrid.api.live.FINAL_CACHE_ROWS` samples (:func:`lean`), and its result named after the source as the user
named it when it ran on a copy (:func:`renamed`).

Imports inside functions: start-up time (a front door: ``import wmrid`` and each function load only what that
function uses).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from typing import Any

from wmrid.core.wheel_log import stream_limits
from wmrid.estimators.result import IdentificationResult

#: Samples in a piece of the final identify's log when it runs lean (CHUNK_ROWS otherwise): 65 s at 1 kHz, 2.6 MB.
FINAL_PIECE_ROWS = 65_536


@contextmanager
def lean(on: bool) -> Iterator[None]:
    """Within, when ``on``: identify reads its log again on each pass instead of keeping it, in pieces of
    FINAL_PIECE_ROWS (:func:`wmrid.core.wheel_log.stream_limits`), runs its passes one after the other on this thread
    (:func:`wmrid.estimators.observer.replay.one_thread_within`: two passes at once hold two pieces and a timing
    window), and, in the command-line process, malloc gives freed memory back at once
    (:func:`wmrid.runtime.limits.lean_malloc`; left so: the command ends with this identify).  The result is the same
    to rounding; the final identify of an hour's stream at 1 kHz peaks 265 MB lower (in a fresh process: 512 ->
    247 MB; caches 415, one thread 309, malloc 272, pieces 247), in 9.1 s instead of 3.7 s."""
    if not on:
        yield
        return
    # the observer's replay (numba kernels): loaded by the identify that follows anyway, not before it
    from wmrid.estimators.observer.replay import one_thread_within
    from wmrid.runtime.limits import lean_malloc  # glibc's mallopt through ctypes: only here

    lean_malloc()
    with one_thread_within(), stream_limits(cache=0, piece=FINAL_PIECE_ROWS):
        yield


def renamed(result: IdentificationResult, path: str, name: str) -> IdentificationResult:
    """``result`` of the copy at ``path`` naming the source as the user named it."""

    def fix(text: Any) -> Any:
        return text.replace(path, name) if isinstance(text, str) else text

    log_info = replace(result.log_info, notes=tuple(fix(n) for n in result.log_info.notes))
    return replace(result, source=name, warnings=tuple(fix(w) for w in result.warnings), log_info=log_info)
