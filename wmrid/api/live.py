"""``wmrid live``: identify a robot while it drives, from a log that is still being written or a Foxglove WebSocket
server (``foxglove_bridge``), and optionally watch it for a change against an identified model.

:func:`live` returns a :class:`LiveRun`: iterating it follows the source (:mod:`wmrid.io.live`), feeds the samples to
the observer as they arrive (the offline kernel, in pieces: :class:`wmrid.estimators.observer.online.OnlineObserver`)
and yields a :class:`LiveUpdate` every ``every`` seconds, then, when the source ends (its end, ``idle`` seconds without
data, ``until`` seconds of log time, ``until_std``), one :class:`LiveResult`.  :meth:`LiveRun.finish` gives that
result at any moment, e.g. after Ctrl-C.

The final result is :func:`wmrid.api.identification.identify` run on exactly the messages received: on the recording
itself when it was read to its end, else on a copy of the bytes read (standard input is spilled to a temporary file
as it arrives), so it is the JSON ``wmrid identify`` writes for them, with every offline check.  The updates before it
carry what can be computed online: the observer's estimate with its jackknife std (before the offline widening
terms: model error, discretisation, slow speeds, the closed-loop check, the efforts' timing).  With ``monitor`` the
samples also go through ``wmrid monitor``'s change test as they arrive
(:class:`wmrid.monitoring.live_monitor.LiveMonitor`), and each change it finds is yielded as a :class:`LiveChange`.
A source that breaks off (a lost connection, a malformed frame: :class:`wmrid.core.errors.StreamError`) ends the run
with the result on what came before it (:attr:`LiveResult.failure`).

Imports inside functions: start-up time (a front door: ``import wmrid`` and each function load only what that
function uses).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from wmrid.api.identification import prepare
from wmrid.api.inputs import LogOptions, reader_arguments
from wmrid.api.live_final import FINAL_PIECE_ROWS as FINAL_PIECE_ROWS, lean, renamed
from wmrid.api.live_observers import fed, first_observers, warm_up
from wmrid.core.errors import UsageError, option
from wmrid.estimators.observer.live_update import LiveUpdate
from wmrid.estimators.options import ObserverOptions
from wmrid.estimators.result import IdentificationResult
from wmrid.model.robot import Robot
from wmrid.monitoring.live_change import LiveChange

__all__ = ["LiveChange", "LiveResult", "LiveRun", "LiveUpdate", "check_output", "live"]

#: The parameters ``until_std`` watches by default: the eight base parameters.
BASE = ("m11", "m12", "m22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")
#: s: how long one poll of the source waits for new data.
POLL_S = 0.05
#: Samples gathered before the observer starts (its start value comes from them when no robot is given).
START_SAMPLES = 50
#: s: how long the process may take, after Ctrl-C or SIGTERM, to identify what it received and write it.
FINISH_GRACE_S = 600.0
#: Samples (about 17 min at 1 kHz) beyond which the final identify runs lean (:func:`wmrid.api.live_final.lean`): its
#: memory then does not grow with the stream's length, for about 2.4 times the time (an hour at 1 kHz: 9.0 s instead
#: of 3.7 s).  Except where identify itself holds a log: the closed-loop check reads a log of up to 2 M samples whole
#: when its prediction error shows a disturbance (wmrid.estimators.feedback.MAX_SAMPLES; 30 min at 1 kHz: 461 MB), as
#: offline.  Samples in a piece of the lean identify's log: FINAL_PIECE_ROWS (wmrid.api.live_final).
FINAL_CACHE_ROWS = 1_048_576


@dataclass(frozen=True)
class LiveResult:
    """How a live run ended, and its result: the last item a :class:`LiveRun` yields.

    Attributes
    ----------
    result
        ``identify`` on the messages received.
    reason
        Why the run ended.
    samples
        The samples received live.
    log_time_s
        s of log time received live.
    read_from
        What the final ``identify`` read.
    stopped
        True when the run was stopped (Ctrl-C, SIGTERM) rather than ended.
    failure
        The source's error when it broke off (a lost connection, a malformed frame; the result is then on what came
        before it), else None.
    """

    result: IdentificationResult
    reason: str
    samples: int
    log_time_s: float
    read_from: str
    stopped: bool = False
    failure: str | None = None

    def to_dict(self, history: bool = False) -> dict[str, Any]:
        """The JSON line ``wmrid live`` prints last in a pipe: the reason and the result (``identify``'s JSON).

        Parameters
        ----------
        history
            Include the result's estimates over time (as :meth:`IdentificationResult.to_dict`).

        Returns
        -------
        dict
            The line, with ``"event": "result"``.
        """
        return {
            "event": "result", "reason": self.reason, "samples": self.samples, "log_time_s": self.log_time_s,
            "read_from": self.read_from, "failure": self.failure, "result": self.result.to_dict(history=history),
        }  # fmt: skip


def _check(name: str, value: float | None, low: float = 0.0) -> None:
    if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value) and value > low):
        raise UsageError(f"{option(name)} must be a number > {low:g}, got {value!r}")


class LiveRun:
    """A live identification (made by :func:`live`): iterate it for the updates and the final :class:`LiveResult`.

    Iterating follows the source, feeds the samples to the observer as they arrive and yields a :class:`LiveUpdate`
    every ``every`` seconds (and, with ``monitor``, a :class:`LiveChange` for each change found), then, when the
    source ends, one :class:`LiveResult`.  :meth:`finish` gives that result at any moment, e.g. after Ctrl-C.

    Parameters
    ----------
    source
        What to follow, as for :func:`live`.
    robot
        The robot, as for :func:`live`.
    observer
        The observer's options (:class:`~wmrid.estimators.options.ObserverOptions`).
    rotor_inertia
        kg m^2, a URDF robot's rotor inertia when it has no rotor links, or None.
    options
        How to read the source (:class:`LogOptions`), or None.
    every
        s of wall time between updates.
    idle
        s without new data that end the run, or None.
    until
        s of log time after which the run ends, or None.
    until_std
        Percent: the run ends once every parameter in ``params`` has a live relative std below it, or None.
    params
        The parameters ``until_std`` watches (None: the eight base parameters).
    reconnect
        Retry a lost WebSocket connection with back-off.
    monitor
        An identified model to watch the stream against, or None; as for :func:`live`.
    """

    def __init__(self, source: str | os.PathLike[str], robot: Any, observer: ObserverOptions,
                 rotor_inertia: float | None, options: LogOptions | None, every: float, idle: float | None,
                 until: float | None, until_std: float | None, params: Sequence[str] | None, reconnect: bool = False,
                 monitor: Any = None) -> None:  # fmt: skip
        from wmrid.io.live.follow import ReaderSettings
        from wmrid.io.live.sources import open_live

        for name, value in (("every", every), ("idle", idle), ("until", until), ("until_std", until_std)):
            _check(name, value)
        self.prep = prepare("auto", observer, options=options, robot=robot, rotor_inertia=rotor_inertia)
        self.settings = observer
        self.options = options
        self.robot = robot
        self.every, self.idle, self.until, self.until_std = every, idle, until, until_std
        from wmrid.estimators.result import REPORTED

        self.params = tuple(params) if params else BASE
        unknown = [p for p in self.params if p not in REPORTED]
        if unknown:
            raise UsageError(f"{option('params')}: {unknown[0]!r} is not one of {', '.join(REPORTED)}")
        args = reader_arguments(options, self.prep.robot)
        self.monitor = self._monitor(monitor, ReaderSettings(**args))
        self.changes: list[LiveChange] = []  # found and not yet handed out
        self.source = open_live(os.fspath(source), ReaderSettings(**args), reconnect)
        warm_up(self.source.tables)
        self.observers: list[tuple[Any, Any]] = []  # (form, OnlineObserver), the one shown first
        self.buffer: list[Any] = []
        self.samples = 0
        self.t_first: float | None = None
        self.t_last: float | None = None
        self.effort_unit = "N m"
        self.notes: list[str] = []
        self.reason: str | None = None
        self.failure: str | None = None
        self.stopped = False
        self.started = time.monotonic()
        self._final: LiveResult | None = None
        self._last = (self.started, 0)  # (time, samples) at the last update

    # -- the change test -----------------------------------------------------------------------------------------
    def _monitor(self, model: Any, reader: Any) -> Any:
        """The change test against ``model`` (a saved identify result: path, dict or result), or None."""
        if model is None:
            return None
        from wmrid.api.monitoring import monitored_model
        from wmrid.io.signals import SignalOptions
        from wmrid.monitoring.live_monitor import LiveMonitor

        unit = reader.signals.effort_label if reader.signals != SignalOptions() else "N m"
        robot = self.prep.robot
        r, b = (getattr(robot.nominal, "r", None), getattr(robot.nominal, "b", None)) if robot else (None, None)
        geometry = (r, b) if r and b else None  # a base set may not know them
        return LiveMonitor(monitored_model(model), geometry=geometry, effort_unit=unit, observer=self.settings)

    # -- the observer ---------------------------------------------------------------------------------------------
    def _start_observers(self) -> None:
        t = np.concatenate([p.t for p in self.buffer])
        eta = np.concatenate([p.eta for p in self.buffer])
        tau = np.concatenate([p.tau for p in self.buffer])
        self.effort_unit = self.buffer[0].effort_unit
        self.observers = first_observers(
            t, eta, tau, self.effort_unit, self.source.name, self.prep, self.settings, self.notes
        )
        self.buffer = []
        self._feed_observers(t, eta, tau)

    def _feed_observers(self, t: np.ndarray, eta: np.ndarray, tau: np.ndarray) -> None:
        self.observers = fed(self.observers, t, eta, tau)

    def _feed(self, piece: Any) -> None:
        if len(piece) == 0:
            return
        if self.t_first is None:
            self.t_first = float(piece.t[0])
        self.t_last = float(piece.t[-1])
        self.samples += len(piece)
        if self.monitor is not None:
            self.changes += self.monitor.feed(piece.t, piece.eta, piece.tau)
        if not self.observers:
            self.buffer.append(piece)
            if sum(len(p) for p in self.buffer) >= START_SAMPLES:
                self._start_observers()
            return
        self._feed_observers(piece.t, piece.eta, piece.tau)

    @property
    def log_time_s(self) -> float:
        return 0.0 if self.t_first is None or self.t_last is None else float(self.t_last - self.t_first)

    # -- the run --------------------------------------------------------------------------------------------------
    def update(self) -> LiveUpdate:
        """The live state now."""
        from wmrid.estimators.observer.online import online_estimate

        now = time.monotonic()
        form_name, parameters, segments = None, {}, 0
        if self.observers:
            form, obs = self.observers[0]
            form_name = form.kind + ("+caster" if form.caster else "")
            est = online_estimate(obs)
            if est is not None:
                parameters, segments = est.parameters, est.segments
        since, count = self._last
        rate = (self.samples - count) / max(now - since, 1e-9)
        self._last = (now, self.samples)
        log_rate = (self.samples - 1) / self.log_time_s if self.log_time_s > 0 else None
        return LiveUpdate(
            source=self.source.name, elapsed_s=now - self.started, samples=self.samples, log_time_s=self.log_time_s,
            rate_hz=rate, log_rate_hz=log_rate, since_last_data_s=now - self.source.last_data, form=form_name,
            parameters=parameters, segments=segments, notes=tuple(self.notes), events=tuple(self._events()),
        )  # fmt: skip

    def _events(self) -> list[str]:
        events = self.source.take_events()
        if self.monitor is not None and self.monitor.notes:
            events += self.monitor.notes
            self.monitor.notes = []
        return events

    def _poll(self, flush: bool = False) -> None:
        """Feed what the source brings in one poll (``flush``: the samples it holds for a larger batch).  A source
        that breaks off (StreamError) after samples came ends the run, keeping them; before, its error is raised."""
        from wmrid.core.errors import StreamError
        from wmrid.runtime import interrupts

        try:
            with interrupts.held():  # a stop lands between two polls: what was read is whole, spilled and counted
                for piece in self.source.flush() if flush else self.source.poll(POLL_S):
                    self._feed(piece)
        except StreamError as err:
            if not self.samples:
                raise
            self.failure = str(err)
            self.reason = f"the source broke off ({err})"

    def _ended(self, now: float) -> str | None:
        if self.source.ended is not None:
            return f"the source ended ({self.source.ended})"
        if self.idle is not None and self.samples and self.source.quiet() >= self.idle:  # once data has come
            return f"no data for {self.idle:g} s ({option('idle')})"
        if self.until is not None and self.log_time_s >= self.until:
            return f"{self.log_time_s:.3f} s of log time received ({option('until')} {self.until:g})"
        return None

    def _precise(self, upd: LiveUpdate) -> bool:
        if self.until_std is None or not upd.parameters:
            return False
        return all(upd.relative_std(p) * 100.0 < self.until_std for p in self.params)

    def __iter__(self) -> Iterator[LiveUpdate | LiveChange | LiveResult]:
        if self._final is not None:
            yield self._final
            return
        next_refresh = self.started + self.every
        while self.reason is None:
            self._poll()
            while self.changes:
                yield self.changes.pop(0)
            now = time.monotonic()
            self.reason = self.reason or self._ended(now)
            if now >= next_refresh or self.reason is not None:
                if self.reason is None:
                    self._poll(flush=True)
                while self.changes:
                    yield self.changes.pop(0)
                upd = self.update()
                if self.reason is None and self._precise(upd):
                    self.reason = (
                        f"every relative std of {', '.join(self.params)} below {self.until_std:g} % "
                        f"({option('until_std')})"
                    )
                yield upd
                next_refresh = now + self.every
        if self.monitor is not None:
            yield from self.monitor.finish()
        yield self.finish()

    def stop(self, reason: str = "stopped") -> None:
        """End the run at the next poll (or now, for :meth:`finish`).

        Parameters
        ----------
        reason
            Why the run ended.
        """
        if self.reason is None:
            self.reason = reason
            self.stopped = True

    def finish(self, stopped_by: str | None = None) -> LiveResult:
        """The final result: ``identify`` on the messages received.

        ``identify`` runs on the recording itself when it was read to its end, else on a copy of the bytes read
        (standard input is spilled to a temporary file as it arrives), so its result is the JSON ``wmrid identify``
        writes for them, with every offline check.

        Parameters
        ----------
        stopped_by
            Names a stop (Ctrl-C, SIGTERM), after which the process is given FINISH_GRACE_S to identify and write;
            None: the run ended by itself.

        Returns
        -------
        LiveResult
            The result (the same one on every call).
        """
        from wmrid.api.identification import identify
        from wmrid.core.errors import WmridError

        if self._final is not None:
            return self._final
        if stopped_by is not None:
            from wmrid.runtime import interrupts

            interrupts.extend_grace(FINISH_GRACE_S)
            self.stop(stopped_by)
        self.reason = self.reason or "stopped"
        natural = not self.stopped and (self.source.ended is not None or self.reason.startswith("no data"))
        final = self.source.final_input(natural)
        try:
            with lean(self.samples > FINAL_CACHE_ROWS):
                result = identify(final.path, self.prep.robot, options=self.options, observer=self.settings)
        except WmridError as err:
            # what was received is not lost with the result (a stream with a gap, messages dropped on the way, is
            # refused as identify refuses the log): the copy is kept, and the one line says where
            kept = self.source.keep(final)
            if kept is not None and err.args:
                text = str(err.args[0]).replace(final.path, kept)  # the message names the copy where it now is
                err.args = (f"{text}; {kept} keeps the {self.samples:,} samples received", *err.args[1:])
            raise
        finally:
            self.source.close()
        if final.copied:
            result = renamed(result, final.path, final.name)
            read_from = f"a copy of the {self.source.bytes_read:,} bytes read" if final.name != "<stdin>" else (
                f"the {self.source.bytes_read:,} bytes read from standard input")  # fmt: skip
            read_from = final.what or read_from
        else:
            read_from = f"{final.name} itself"
        self._final = LiveResult(
            result, self.reason, self.samples, self.log_time_s, read_from, self.stopped, self.failure
        )
        return self._final

    def close(self) -> None:
        """Release the source without a result (its temporary files are removed)."""
        self.source.close()


def check_output(path: str | os.PathLike[str], force: bool = False) -> None:
    """Refuse, before a run that may take hours, an output file that could not be written at its end (an existing file
    without ``force``, a missing folder); standard output and other streams pass."""
    from pathlib import Path

    from wmrid.runtime.atomic import _check_target, stream_fd

    if stream_fd(str(path)) is None:
        _check_target(Path(path), force)


def live(
    source: str | os.PathLike[str],
    robot: str | os.PathLike[str] | Robot | None = None,
    *,
    options: LogOptions | None = None,
    every: float = 1.0,
    idle: float | None = None,
    until: float | None = None,
    until_std: float | None = None,
    params: Sequence[str] | None = None,
    observer: ObserverOptions | None = None,
    rotor_inertia: float | None = None,
    reconnect: bool = False,
    monitor: str | os.PathLike[str] | dict[str, Any] | IdentificationResult | None = None,
) -> LiveRun:
    """Identify the robot that is writing ``source`` while it writes it.

    The updates carry what can be computed online: the observer's estimate with its jackknife std (before the
    offline widening terms).  The final result is :func:`wmrid.identify` run on exactly the messages received.

    Parameters
    ----------
    source
        ``"-"`` (standard input: CSV rows with a header, JSON lines, or an MCAP stream), a CSV file being appended
        to, an MCAP file being written, a rosbag2 folder being recorded with MCAP storage, or a Foxglove WebSocket
        server ``"ws://HOST:PORT"`` (foxglove_bridge); read with ``options``.
    robot
        As for :func:`wmrid.identify` (the final result is ``identify`` with it).
    options
        How to read ``source``: the same :class:`LogOptions` as :func:`wmrid.identify` (topics, joints, field
        paths).
    every
        s of wall time between updates.
    idle
        s without new data that end the run, once samples have come (None: wait).
    until
        s of log time after which the run ends (None: no limit).
    until_std
        Percent: the run ends once every parameter in ``params`` has a live relative std below it.
    params
        The parameters ``until_std`` watches (None: all eight base parameters).
    observer
        As for :func:`wmrid.identify` (the final result is ``identify`` with it).
    rotor_inertia
        kg m^2, a URDF robot's rotor inertia when it has no rotor links.
    reconnect
        A WebSocket source whose connection is lost is retried with back-off (else the run ends, keeping what came:
        :attr:`LiveResult.failure`).
    monitor
        An identified model (a saved ``identify`` result: its path or JSON as a dict, or the result) that the stream
        is watched against with ``wmrid monitor``'s change test: a :class:`LiveChange` is yielded as soon as the test
        alarms (:class:`wmrid.monitoring.live_monitor.LiveMonitor`).

    Returns
    -------
    LiveRun
        The run; iterating it yields :class:`LiveUpdate` objects (and :class:`LiveChange` objects with ``monitor``),
        then one :class:`LiveResult`.

    Raises
    ------
    UsageError
        ``every``, ``idle``, ``until`` or ``until_std`` not a number > 0, or an unknown name in ``params``.
    """
    observer = observer if observer is not None else ObserverOptions()
    return LiveRun(
        source, robot, observer, rotor_inertia, options, every, idle, until, until_std, params, reconnect, monitor
    )
