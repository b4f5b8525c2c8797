"""The efforts' timing against the speeds on a whole log: the timing check identify runs by default
(:func:`timing_check`, a window of the log profiled by :func:`wmrid.estimators.delay.estimate_delay`), a delay applied
(:func:`apply_delay`), and the delay a check could not resolve (:func:`unresolved_delay`), which the std then
carries."""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from wmrid.core.errors import UsageError, WmridError, option
from wmrid.core.wheel_log import LogStream, WheelLog, shifted_stream
from wmrid.estimators.delay import DEFAULT_SPAN_S, SIGNIFICANT_S, SIGNIFICANT_Z, DelayEstimate, combine, estimate_delay
from wmrid.estimators.findings import DelayApplied, TimingCheck
from wmrid.estimators.uncertainty import interval_factor


def faster_controller(est: Any, t: np.ndarray, torque_hold: str, control_rate: float | None) -> bool:
    """Whether a significant delay estimate ``est`` (:class:`wmrid.estimators.delay.DelayEstimate`) is the signature
    of a
    controller faster than the log rather than of two clocks: under the default hold over each logged step (zoh,
    no --control-rate) the efforts act half a step after their stamps, while a faster controller's act after
    half of its own, shorter period; the estimate then lies between 0 and half a logged step (within 2 std).
    Measured on multibody logs of a 1 kHz controller at 100 Hz: 3.9-5.8 ms, half a step being 5 ms."""
    if torque_hold != "zoh" or control_rate is not None or len(t) < 2:
        return False
    half = 0.5 * float(np.median(np.diff(np.asarray(t, dtype=np.float64))))
    return -2 * est.std < est.delay <= half + 2 * est.std


#: Hz: a log slower than this whose controller rate is unknown has its hold uncertain (:func:`timing_check`): its
#: half step is more than 1.25 ms, beyond DELAY_RESOLUTION_S even against a 1 kHz controller's half period.
SLOW_LOG_HZ = 400.0


#: The timing check profiles at most this many samples from the start of a log (200 s at 1 kHz): a clock offset or a
#: controller's hold is the same all along a log, and 40 s already pin it to 0.07 ms; memory and time stay bounded.
TIMING_WINDOW_SAMPLES = 200_000


def search_span(t: np.ndarray) -> float:
    """s: the delay search's half-width for a log with times t (n,) s: DEFAULT_SPAN_S, or 1.2 logged steps when
    longer (a slow log's held effort can lag its stamp by half a step: 25 ms at 20 Hz)."""
    step = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    return max(DEFAULT_SPAN_S, 1.2 * step)


def faster_controller_text(est: Any, t: np.ndarray) -> str:
    """The warning for a faster controller found by ``est`` on a log with times t (n,) s."""
    half = 0.5 * float(np.median(np.diff(t)))
    return (
        f"the efforts act {max(half - est.delay, 0.0) * 1e3:.2f} +/- {est.std * 1e3:.2f} ms after their "
        f"stamps, not half a logged step ({half * 1e3:.3g} ms) as an effort held over each step would: a "
        "controller faster than the log set them (the log holds one of its updates per step); give "
        "--control-rate HZ (e.g. 1000 for a 1 kHz loop) or --torque-hold foh"
    )


def timing_check(
    log: Any, torque_hold: str, control_rate: float | None, samples: int, median_step: float, form: Any = None
) -> TimingCheck:
    """The record for ``diagnostics.timing``: the efforts' delay estimated from the log (:func:`estimate_delay`,
    searched over +/- max(DEFAULT_SPAN_S, 1.2 logged steps), under the given hold), for identify's default timing.

    Keys: "checked"; the estimate (:meth:`DelayEstimate.to_dict`; by instrumental variables when the log carries the
    wheel-speed reference, else least squares); "apply": significant and not at the edge of the search (identify
    then identifies with ``delay="auto"``); "slow": the log is slower than SLOW_LOG_HZ; "faster_controller":
    :func:`faster_controller` (the warning of :func:`apply_delay` then names --control-rate).
    Measured on the light AMR (1 kHz controller, noise): 5 ms late or early at 1 kHz found within 0.1 ms on the
    sinusoid; a 100 Hz log 4.5 ms of the 5 ms half step, a 20 Hz log 24.6 of 25 ms.  The profile costs one
    regression (0.03 s for 40 s at 1 kHz) per window of at most TIMING_WINDOW_SAMPLES samples, read piece by piece
    (``samples`` and ``median_step`` s come from the survey); a longer log is profiled window by window and the
    windows' estimates combined by their inverse variances (:func:`combine`), so the delay's std keeps shrinking
    as 1/sqrt(T) with the log's length.  A log that cannot be profiled (a hole, too short for the filter) is not
    checked, and the record says why.  ``form``: the friction model profiled (:func:`estimate_delay`)."""
    slow = bool(median_step > 0 and 1.0 / median_step < SLOW_LOG_HZ)
    none = TimingCheck(checked=False, apply=False, slow=slow, faster_controller=False)
    if samples < 2:
        return replace(none, why=f"{samples} samples")
    try:
        wheel, drag, first_t, profiled, windows = _windowed(log, samples, torque_hold, control_rate, form)
    except WmridError as err:
        return replace(none, why=str(err))
    est, note = with_drag(wheel, drag, form)
    apply = bool(est.significant and not est.at_edge)
    faster = bool(apply and faster_controller(est, first_t, torque_hold, control_rate))
    # the eight base parameters' slope (a caster model profiled has its drag after them, named by its own form)
    slope = est.theta0_slope[:8].tolist() if est.theta0_slope is not None else None
    return TimingCheck(
        checked=True, estimate=est.record(), apply=apply, slow=slow, faster_controller=faster,
        samples_profiled=profiled, of=int(samples), windows=windows,
        profiled_with=None if drag is None else (form.friction if est is drag else "wheel"),
        wheel_model=None if drag is None else wheel.record(), note=note or None, theta0_slope_per_s=slope,
    )  # fmt: skip


def profile_windows(
    log: Any, samples: int, torque_hold: str, control_rate: float | None, form: Any
) -> tuple[DelayEstimate, int, int, np.ndarray]:
    """The delay profiled window by window over a log of ``samples`` samples (windows of at most
    TIMING_WINDOW_SAMPLES, of equal size; a short tail is left out), the windows' estimates combined by their inverse
    variances (:func:`combine`): (estimate, samples profiled, windows, t (m,) s of the first window).  A
    :class:`wmrid.core.wheel_log.LogStream` is read piece by piece (one window in memory).  ``form``: the friction
    model profiled (:func:`estimate_delay`; None: the wheels' friction alone).  Raises :class:`WmridError` when the
    first window cannot be profiled."""
    memo = _profiles.setdefault(log, {}) if isinstance(log, LogStream) else {}
    key = (samples, torque_hold, control_rate, form)
    if key not in memo:
        memo[key] = _profile_windows(log, samples, torque_hold, control_rate, form)
    return memo[key]


#: The windowed profiles made of a stream, by (samples, hold, control rate, form): a long log whose timing check
#: finds a delay applies that same estimate (:func:`apply_delay`), and its windows are read and fitted once, not twice.
_profiles: weakref.WeakKeyDictionary[Any, dict[tuple[Any, ...], tuple[DelayEstimate, int, int, np.ndarray]]] = (
    weakref.WeakKeyDictionary()
)


def _profile_windows(
    log: Any, samples: int, torque_hold: str, control_rate: float | None, form: Any
) -> tuple[DelayEstimate, int, int, np.ndarray]:
    count = math.ceil(samples / TIMING_WINDOW_SAMPLES)
    size = math.ceil(samples / count)
    estimates: list[DelayEstimate] = []
    profiled = 0
    first_t = None
    for t, eta, tau, reference in _windows(log if isinstance(log, LogStream) else None, log, size):
        if estimates and len(t) < size // 2:  # a short tail adds little and may not fit the filter
            break
        # the filter's cutoff follows the log's bandwidth and noise, the same all along a log as its delay: chosen
        # once, on the first window (IDIM's choice fits the log several times: half the check's time on an hour)
        cutoff = estimates[0].cutoff_hz if estimates else None
        try:
            est = estimate_delay(
                t, eta, tau, span=search_span(t), torque_hold=torque_hold, control_rate=control_rate,
                reference=reference, form=form, cutoff_hz=cutoff,
            )  # fmt: skip
        except WmridError:
            if not estimates:
                raise
            break
        estimates.append(est)
        profiled += len(t)
        first_t = t if first_t is None else first_t
    assert first_t is not None
    return combine(estimates), profiled, len(estimates), first_t


def consults_drag(wheel: DelayEstimate) -> bool:
    """Whether the timing needs the profile with the casters' drag too (:func:`with_drag`): the wheels' friction alone
    found a significant delay, which an undescribed drag can fake."""
    return bool(wheel.significant and not wheel.at_edge)


def with_drag(wheel: DelayEstimate, drag: DelayEstimate | None, form: Any) -> tuple[DelayEstimate, str | None]:
    """The estimate the timing rests on, from the profile with the wheels' friction alone (``wheel``) and, when
    :func:`consults_drag`, the profile with the casters' drag too (``drag``, of friction model ``form``; None: not run
    or failed).  A drag the profile leaves out is fitted by shifting the efforts, so a significant delay stands only
    when the drag's profile finds it too (its figure is then the one applied); otherwise the drag's profile is the
    record, nothing is applied, and the note says why.  The check only ever vetoes: a wheels' profile that is not
    significant, or runs to the edge of its search, is kept as it is, because a delay only the drag's profile shows
    can be its own misfit (the light AMR reversing on MuJoCo, on time, came out 5.6 ms late with the casters'
    two-term model).  Returns (estimate, note or None).

    Measured (MuJoCo, the paper robot with its two ball casters, whose drag is about five times the wheels' Coulomb
    friction; speed noise 0.02 rad/s, no delay): on its 60 s plan the wheels' profile put the efforts 18.5 +/- 2.4 ms
    late, "significant" (identify applied it: S 132, every parameter poorly determined); with the casters' load model
    0.04 +/- 0.11 ms.  REGBOT's wheels' profile is determined and not significant (+6.62 +/- 1.64 ms): timed as
    before."""
    if drag is None or not consults_drag(wheel):
        return wheel, None
    if drag.significant and not drag.at_edge:
        return drag, None
    found = f"{drag.delay * 1e3:+.2f} +/- {drag.std * 1e3:.2f} ms" if drag.determined else "not pinned"
    return drag, (
        f"with the wheels' friction alone the efforts appear {wheel.delay * 1e3:+.2f} +/- {wheel.std * 1e3:.2f} ms "
        f"late, but with the casters' drag modelled ({form.friction}) the delay is {found}: the undescribed drag, "
        "not a delay, so the efforts are used as stamped"
    )


#: A delay the timing check could not resolve is carried by the std when it would move some parameter by more
#: than this many of its std (the std then grows by more than 4 %); below, the extra identification is skipped.
MATERIAL_SHIFT = 0.3


#: Coverage of the evidence a delay left unapplied needs before the std carries it (Student's t with the profile's
#: G - 1 dof: |d| beyond about 2 std).
CARRY_COVERAGE = 0.95


def unresolved_delay(record: TimingCheck, theta0_std: np.ndarray) -> float | None:
    """The delay s whose effect the std must carry when the timing check (``record``, :func:`timing_check`) left the
    efforts as stamped: sign(d) sqrt(d^2 - s^2), the unbiased estimate of the delay's size when the log puts it at
    d +/- s (E[d^2] = delta^2 + s^2), when the log gives evidence of a delay: |d| beyond the t quantile at
    CARRY_COVERAGE (about 2 std) but not significant.  None when the check applied its delay, did not run, ended at
    the edge of its search or did not pin the delay (an infinite std), when the log shows no such evidence, when it
    rules out a significant delay (|d| + SIGNIFICANT_Z s <= SIGNIFICANT_S: below the resolution the check applies),
    or when that delay would move no parameter by MATERIAL_SHIFT of its std ``theta0_std`` (n0,) (judged by the
    profile's slope, ``theta0_slope_per_s``).

    Why: a delay below significance is not applied, but on a log that times its efforts poorly (a slow reversing
    motion with torque noise: std 1-1.6 ms) a 5 ms delay can fall below it and bias the friction by 7 % at 5 std,
    with nothing said.  Why not sqrt(d^2 + s^2), what this carried before issue 28: on a log on one clock it
    carried a delay of the size of its std on every log, so the std of a log that pins its delay poorly (a 200 Hz
    reversing log with a disturbance inside the loop: s of 5-45 ms) grew 4-5 times against --delay 0; on a log
    with no delay the term now comes in 5 % of logs, and where it does its size, like s, shrinks as 1/sqrt(T)."""
    est = record.estimate
    if not record.checked or record.apply or est is None or est.at_edge_of_search:
        return None
    slope = record.theta0_slope_per_s
    d, s = est.delay_s, est.std_s
    if slope is None or d is None or s is None or not (math.isfinite(d) and math.isfinite(s)):
        return None
    d, s = float(d), float(s)
    if abs(d) + SIGNIFICANT_Z * s <= SIGNIFICANT_S:
        return None  # the log rules out any delay the check would call significant
    segments = 2 if est.segments is None else est.segments
    if abs(d) <= interval_factor(CARRY_COVERAGE, max(int(segments) - 1, 1)) * s:
        return None  # no evidence of a delay
    size = math.sqrt(d * d - s * s)
    slope = np.asarray(slope, dtype=float)
    std = np.asarray(theta0_std, dtype=float)[: len(slope)]
    with np.errstate(divide="ignore", invalid="ignore"):
        shift = np.abs(size * slope[: len(std)]) / std
    if not np.any(np.isfinite(shift) & (shift > MATERIAL_SHIFT)):
        return None
    return math.copysign(size, d)


def unresolved_text(record: TimingCheck, moved: float) -> str:
    """The warning for an unresolved delay (:func:`unresolved_delay`) ``moved`` s, the timing check's ``record``."""
    est = record.estimate
    assert est is not None, "an unresolved delay was estimated"
    assert est.delay_s is not None, "an unresolved delay is finite"
    assert est.std_s is not None, "an unresolved delay's std is finite"
    return (
        f"the efforts' timing against the speeds is uncertain: the log puts their delay at "
        f"{est.delay_s * 1e3:+.2f} +/- {est.std_s * 1e3:.2f} ms, not distinguishable from none, so they "
        f"were used as stamped; what a delay of {moved * 1e3:+.2f} ms would change was added to the std. Give "
        "--delay 0 if the two clocks are known to agree (or --delay SECONDS if the offset is known)"
    )


def _window(stream: Any, log: Any, most: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t (m,), eta (m, 2), tau (m, 2)): the first ``most`` samples of a log, from the stream's pieces when it is a
    :class:`wmrid.core.wheel_log.LogStream` (read no further), else sliced from the log in memory."""
    t, eta, tau, _ = next(_windows(stream, log, most))
    return t, eta, tau


def _reference_of(log: Any, n: int) -> np.ndarray | None:
    """The log's wheel-speed reference (n, 2) when it has one of that shape (a simulator's ``reference`` may be a
    pose), else None."""
    ref = getattr(log, "reference", None)
    if ref is None:
        return None
    ref = np.asarray(ref, dtype=np.float64)
    return ref if ref.shape == (n, 2) else None


def _windows(stream: Any, log: Any, size: int) -> Any:
    """Consecutive windows (t, eta, tau, reference or None) of at most ``size`` samples covering a log, from the
    stream's pieces when it is a :class:`wmrid.core.wheel_log.LogStream` (read piece by piece; one window in
    memory at a time), else sliced from the log in memory."""
    if stream is None:
        arrays = [np.asarray(a, dtype=np.float64) for a in (log.t, log.eta, log.tau)]
        reference = _reference_of(log, len(arrays[0]))
        for start in range(0, len(arrays[0]), size):
            cut = slice(start, start + size)
            yield (*(a[cut] for a in arrays), None if reference is None else reference[cut])
        return
    parts: list[Any] = []
    count = 0

    def window(parts: list[Any]) -> tuple[Any, ...]:
        t = np.concatenate([p.t for p in parts]).astype(np.float64, copy=False)
        eta = np.concatenate([p.eta for p in parts]).astype(np.float64, copy=False)
        tau = np.concatenate([p.tau for p in parts]).astype(np.float64, copy=False)
        refs = [getattr(p, "reference", None) for p in parts]
        reference = None
        if all(r is not None for r in refs):
            reference = np.concatenate(refs).astype(np.float64, copy=False)
            reference = reference if reference.shape == (len(t), 2) else None
        return t, eta, tau, reference

    for piece in stream:
        parts.append(piece)
        count += len(piece.t)
        while count >= size:
            t, eta, tau, reference = window(parts)
            ref_head = ref_rest = None
            if reference is not None:
                ref_head, ref_rest = reference[:size], reference[size:]
            yield t[:size], eta[:size], tau[:size], ref_head
            rest = t[size:]
            parts = [] if len(rest) == 0 else [_Piece(rest, eta[size:], tau[size:], ref_rest)]
            count = len(rest)
    if count:
        yield window(parts)


@dataclass(frozen=True)
class _Piece:
    """What :func:`_windows` carries over from one window to the next."""

    t: np.ndarray
    eta: np.ndarray
    tau: np.ndarray
    reference: np.ndarray | None


def apply_delay(
    log: Any, delay: float | str, torque_hold: str, control_rate: float | None, form: Any = None
) -> tuple[Any, DelayApplied, list[str]]:
    """(the log with its efforts read ``delay`` s earlier, the record for ``diagnostics.delay``, warnings) for
    :func:`wmrid.pipeline.identify.identify`: in memory, or, for a :class:`wmrid.core.wheel_log.LogStream` longer
    than the timing check's window (TIMING_WINDOW_SAMPLES; its ``samples`` known from a pass), a stream that is
    never read whole (:func:`_apply_delay_stream`).  "auto" on a log longer than that window, in memory or not, is the
    windows' combined estimate, the figure the timing check (``diagnostics.timing``) shows.

    ``delay``: seconds, or "auto" (:func:`estimate_delay`; applied only when significant and not at the edge
    of the search; ``form`` the friction model profiled).  The warnings name the likely cause: two clocks, or a
    controller faster than the log."""
    # IDIM's rows (~10 ms): only when a delay is applied
    from wmrid.estimators.regression.idim_rows import shifted

    if in_pieces(log):
        return _apply_delay_stream(log, log.samples, delay, torque_hold, control_rate, form)
    whole = log.read() if isinstance(log, LogStream) else log
    t = np.asarray(whole.t, dtype=np.float64)
    eta = np.asarray(whole.eta, dtype=np.float64)
    tau = np.asarray(whole.tau, dtype=np.float64)
    warnings: list[str] = []
    if delay == "auto" and len(t) > TIMING_WINDOW_SAMPLES:  # the timing check's own estimate, window by window
        wheel, drag, first_t, _, _ = _windowed(whole, len(t), torque_hold, control_rate, form)
        applied, record = _decided(wheel, drag, form, first_t, torque_hold, control_rate, warnings)
    elif delay == "auto":
        common = {
            "span": search_span(t), "torque_hold": torque_hold, "control_rate": control_rate,
            "reference": _reference_of(whole, len(t)),
        }  # fmt: skip
        wheel, drag = _wheel_and_drag(lambda with_form: estimate_delay(t, eta, tau, form=with_form, **common), form)
        applied, record = _decided(wheel, drag, form, t, torque_hold, control_rate, warnings)
    else:
        applied, record = _given(delay)
    if applied == 0.0:
        return whole, record, warnings
    shifted_log = WheelLog(
        t=t, eta=eta, tau=shifted(t, tau, -applied), source=getattr(whole, "source", "log"),
        notes=tuple(getattr(whole, "notes", ())), effort_unit=getattr(whole, "effort_unit", "N m"),
        pose=getattr(whole, "pose", None), reference=getattr(whole, "reference", None),
    )  # fmt: skip
    return shifted_log, record, warnings


def in_pieces(log: Any) -> bool:
    """Whether a delay is applied to ``log`` piece by piece (:func:`_apply_delay_stream`) rather than in memory: a
    :class:`wmrid.core.wheel_log.LogStream` longer than the timing check's window (its length known from a pass)."""
    return isinstance(log, LogStream) and log.samples is not None and log.samples > TIMING_WINDOW_SAMPLES


def _apply_delay_stream(
    log: Any, samples: int, delay: float | str, torque_hold: str, control_rate: float | None, form: Any
) -> tuple[Any, DelayApplied, list[str]]:
    """:func:`apply_delay` for a log longer than the timing check's window, read piece by piece, never whole: the
    delay "auto" is the windows' combined estimate (:func:`profile_windows`, the one ``diagnostics.timing`` shows), the
    efforts are shifted as the pieces pass (:func:`wmrid.core.wheel_log.shifted_stream`, the same values as in
    memory).  Memory: a window and a piece, whatever the log's length."""
    warnings: list[str] = []
    if delay == "auto":
        wheel, drag, first_t, _, _ = _windowed(log, samples, torque_hold, control_rate, form)
        applied, record = _decided(wheel, drag, form, first_t, torque_hold, control_rate, warnings)
    else:
        applied, record = _given(delay)
    if applied == 0.0:
        return log, record, warnings
    return shifted_stream(log, -applied), record, warnings


def _windowed(
    log: Any, samples: int, torque_hold: str, control_rate: float | None, form: Any
) -> tuple[DelayEstimate, DelayEstimate | None, np.ndarray, int, int]:
    """(the wheels' profile, the drag's or None, t (m,) s of the first window, samples profiled, windows) window by
    window (:func:`profile_windows`): the estimate ``diagnostics.timing`` shows.  Raises :class:`WmridError` when the
    wheels' profile cannot be made."""
    runs: list[tuple[DelayEstimate, int, int, np.ndarray]] = []

    def profile(with_form: Any) -> DelayEstimate:
        runs.append(profile_windows(log, samples, torque_hold, control_rate, with_form))
        return runs[-1][0]

    wheel, drag = _wheel_and_drag(profile, form)
    _, profiled, windows, first_t = runs[0]
    return wheel, drag, first_t, profiled, windows


def _wheel_and_drag(profile: Any, form: Any) -> tuple[DelayEstimate, DelayEstimate | None]:
    """(the wheels' friction profiled: ``profile(None)``, the casters' drag profiled too: ``profile(form)`` when the
    first consults it, :func:`consults_drag`; None when not, or when it fails) for :func:`with_drag`."""
    wheel = profile(None)
    if form is None or not consults_drag(wheel):
        return wheel, None
    try:
        return wheel, profile(form)
    except WmridError:
        return wheel, None


def _given(delay: float | str) -> tuple[float, DelayApplied]:
    """(the delay s, its record) for a delay given in seconds (``--delay``)."""
    # IDIM's rows (~10 ms): only when a delay is applied
    from wmrid.estimators.regression.idim_rows import MAX_EFFORT_SHIFT_S

    applied = float(delay)
    if not (math.isfinite(applied) and abs(applied) <= MAX_EFFORT_SHIFT_S):
        raise UsageError(f"{option('delay')} must be auto or seconds within +/-{MAX_EFFORT_SHIFT_S:g}, got {delay!r}")
    return applied, DelayApplied(chosen_by="--delay", applied_s=applied)


def _decided(
    wheel: DelayEstimate,
    drag: DelayEstimate | None,
    form: Any,
    t: np.ndarray,
    torque_hold: str,
    control_rate: float | None,
    warnings: list[str],
) -> tuple[float, DelayApplied]:
    """(the delay s applied, its record) for the delay estimated as ``wheel`` (and ``drag``, :func:`with_drag`) on a
    log with times ``t`` (n,) s (its first window for a long log); what it says is appended to ``warnings``."""
    est, note = with_drag(wheel, drag, form)
    record = DelayApplied(chosen_by="auto", estimate=est.record())
    if drag is not None:
        record = replace(record, profiled_with=form.friction if est is drag else "wheel", wheel_model=wheel.record())
    if note:
        warnings.append(note)
    applied = est.delay if est.significant and not est.at_edge else 0.0
    if est.at_edge:
        warnings.append(
            f"the delay between efforts and speeds could not be estimated (the fit keeps improving to the edge of "
            f"the searched +/-{abs(est.grid[0]) * 1e3:g} ms): the model does not fit this log well enough to time "
            "it; the efforts are used as stamped"
        )
    elif not est.determined:
        why = (
            "the instrumental-variable moment of the logged reference does not cross zero within the searched "
            f"+/-{abs(est.grid[0]) * 1e3:g} ms"
            if est.method == "instrumental variables"
            else "the fit on part of the log keeps improving to the edge of the searched "
            f"+/-{abs(est.grid[0]) * 1e3:g} ms"
        )
        warnings.append(
            f"the delay between efforts and speeds could not be estimated ({why}): this log does not pin it; the "
            "efforts are used as stamped"
        )
    elif est.significant and faster_controller(est, t, torque_hold, control_rate):
        warnings.append(
            f"{faster_controller_text(est, t)}.  This run read them {est.delay * 1e3:.2f} ms later than the hold "
            f"assumes (--delay {est.delay:.5f})"
        )
    elif est.significant:
        half = 0.5 * float(np.median(np.diff(t)))
        cause = "two topics or clocks?"
        if abs(est.delay + half) <= max(2 * est.std, 0.2 * half):
            cause = "half a logged step: speeds computed as backward differences of encoder counts lag by that much"
        warnings.append(
            f"the efforts appear stamped {est.delay * 1e3:+.2f} +/- {est.std * 1e3:.2f} ms late against the "
            f"speeds ({cause}): they were read that much earlier (--delay "
            f"{est.delay:.5f}); a delay left in biases the friction by tens of per cent"
        )
    return applied, replace(record, applied_s=applied)
