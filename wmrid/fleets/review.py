"""A fleet's table read for what matters: which robot's friction creeps up, which one now carries a payload, which
one no longer matches its siblings (:func:`review_fleet`).  The statistics are in
:mod:`wmrid.fleets.changes`; this module groups the table's rows by robot, words the findings and ranks
the robots by the evidence against them.
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wmrid.fleets.changes import (
    FRICTION,
    MIN_EFFECT_STDS,
    MONITORED,
    SENSITIVITY_RAMP_LOGS,
    WHEEL_FRICTION,
    WHEEL_OF,
    RobotHistory,
    analyse_robot,
    detectable,
    friction_at,
    leave_one_out_t,
    outlier_threshold,
)
from wmrid.model.payload import PAYLOAD_NAMES, payload_from_change

#: The table columns of each wheel's friction at its typical speed: (Fw name, Fv, Fd, speed, correlation).
_WHEEL_COLUMNS = (("Fw1", "Fv1", "Fd1", "speed_r", "Fv1_Fd1_corr"), ("Fw2", "Fv2", "Fd2", "speed_l", "Fv2_Fd2_corr"))

#: Robots of one model needed to say which one stands out.
MIN_FLEET = 5
NO_MODEL = "(no robot file)"


@dataclass
class RobotReview:
    """One robot: its usable logs (rows, in time order), failed logs, the change analysis, the findings in words
    (``findings``) and as short tags (``flags``), its fleet t beyond the threshold (``outlier``), a payload
    estimate, and the evidence against it (statistic / threshold; > 1 is flagged)."""

    robot_id: str
    model: str
    rows: list[dict[str, Any]]
    failed: int
    history: RobotHistory
    findings: list[str] = field(default_factory=list)
    flags: list[str] = field(default_factory=list)
    outlier: dict[str, float] = field(default_factory=dict)
    payload: dict[str, tuple[float, float | None]] | None = None
    evidence: float = 0.0
    #: True when some log has no start time: logs in name order, rates per log instead of per day
    per_log: bool = False
    #: {Fw name: (the wheel's typical speed in rad/s, values (T,), standard errors (T,))}: each wheel's friction
    #: torque at the median of its mean speeds over the baseline logs (none when the table has no speeds)
    wheel_friction: dict[str, tuple[float, np.ndarray, np.ndarray]] = field(default_factory=dict)
    #: The smallest changes flagged at least half the time, relative to the baseline mean (:func:`_sensitivity`):
    #: {"step": {parameter: size on its first log}, "ramp": {parameter: rise over "ramp_logs" logs}, "ramp_logs"}
    sensitivity: dict[str, Any] = field(default_factory=dict)
    #: The same in words (empty for a robot with too few logs to test)
    sensitivity_text: str = ""

    @property
    def flagged(self) -> bool:
        return bool(self.flags)

    @property
    def watched(self) -> tuple[str, ...]:
        """The parameters scanned for changes: :data:`MONITORED`, then the wheel friction torques it has."""
        return (*MONITORED, *self.wheel_friction)

    def series(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(values (T,), standard errors (T,), NaN where unknown) of one watched parameter over the usable logs."""
        if name in self.wheel_friction:
            return self.wheel_friction[name][1], self.wheel_friction[name][2]
        values = np.array([r[name] for r in self.rows], dtype=float)
        stds = np.array([r.get(f"{name}_std") if r.get(f"{name}_std") is not None else np.nan for r in self.rows],
                        dtype=float)  # fmt: skip
        return values, stds

    def describe(self, name: str) -> str:
        """A parameter's name as the findings say it (a wheel friction torque with its speed)."""
        if name in self.wheel_friction:
            return f"{name} (the {WHEEL_OF[name]} wheel's friction at {self.wheel_friction[name][0]:.3g} rad/s)"
        return name

    def time_of(self, index: int) -> dt.datetime | None:
        return self.rows[index]["start_time"] if 0 <= index < len(self.rows) else None

    def label_of(self, index: int) -> str:
        """A log's time stamp (its date; with the time when two logs share a day), else its path."""
        when = self.time_of(index)
        if when is None:
            return str(self.rows[index]["log"])
        same_day = sum(1 for r in self.rows if r["start_time"] is not None and r["start_time"].date() == when.date())
        return when.strftime("%Y-%m-%d %H:%M") if same_day > 1 else when.strftime("%Y-%m-%d")


@dataclass
class FleetReview:
    """The fleet's robots ranked by the evidence against them, the settings and the statements of what the
    thresholds mean."""

    robots: list[RobotReview]
    settings: dict[str, Any]
    statements: list[str]
    outlier_thresholds: dict[str, tuple[int, float]]


def usable(row: dict[str, Any]) -> bool:
    """A row identified without error with every watched parameter finite."""
    if row.get("error") is not None:
        return False
    return all(row.get(n) is not None and math.isfinite(row[n]) for n in MONITORED)


def _days(rows: list[dict[str, Any]]) -> np.ndarray:
    times = [r["start_time"] for r in rows]
    if all(t is not None for t in times) and times:
        return np.array([(t - times[0]).total_seconds() / 86400.0 for t in times])
    return np.arange(len(rows), dtype=float)


def _order(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    far = dt.datetime.max.replace(tzinfo=dt.timezone.utc)
    return sorted(rows, key=lambda r: (r["start_time"] or far, str(r["log"])))


def review_fleet(
    rows: Sequence[dict[str, Any]],
    *,
    baseline: int = 10,
    window: int = 30,
    alpha: float = 0.001,
    outlier_alpha: float = 0.001,
    robot_of: Callable[[str], Any] | None = None,
) -> FleetReview:
    """The review of a fleet table's rows (:func:`wmrid.fleets.table.read_table`).

    baseline, window, alpha : :func:`~wmrid.fleets.changes.analyse_robot`'s settings (alpha: the
        probability of flagging a robot without change over its history).
    outlier_alpha : the probability that any robot of a model with Gaussian unit-to-unit spread is said to stand
        out.
    robot_of : robot file or name -> :class:`~wmrid.model.robot.Robot` or None (its r and b turn a change of M and
        V_c into a payload estimate).
    """
    if not 0 < alpha < 0.5 or not 0 < outlier_alpha < 0.5:
        raise ValueError("alpha and outlier_alpha must be in (0, 0.5)")
    by_robot: dict[str, list[dict[str, Any]]] = {}
    seen: set[tuple[str, str]] = set()
    repeats = 0
    for row in rows:  # a log identified again under other options is one log: its first row in the table counts
        key = (str(row["robot_id"]), str(row.get("sha256") or row["log"]))
        if key in seen:
            repeats += 1
            continue
        seen.add(key)
        by_robot.setdefault(str(row["robot_id"]), []).append(row)
    reviews = []
    for robot_id, robot_rows in sorted(by_robot.items()):
        ok = _order([r for r in robot_rows if usable(r)])
        models = {r["robot"] for r in robot_rows if r.get("robot")}
        model = sorted(models)[0] if models else NO_MODEL
        review = RobotReview(robot_id, model, ok, len(robot_rows) - len(ok), RobotHistory(len(ok), math.inf),
                             per_log=any(r["start_time"] is None for r in ok))  # fmt: skip
        review.wheel_friction = _wheel_friction(review, baseline)
        names = review.watched
        pairs = [review.series(n) for n in names]
        values = np.array([v for v, _ in pairs], dtype=float).reshape(len(names), len(ok)).T
        stds = np.array([e for _, e in pairs], dtype=float).reshape(len(names), len(ok)).T
        review.history = analyse_robot(values, stds, _days(ok), names=names, baseline=baseline, window=window,
                                       alpha=alpha, unfloored=WHEEL_FRICTION)  # fmt: skip
        review.evidence = review.history.evidence
        review.sensitivity, review.sensitivity_text = _sensitivity(review, baseline, window)
        if len(models) > 1:
            review.findings.append(f"its logs name {len(models)} robot files ({', '.join(sorted(models))}); the "
                                   f"fleet comparison uses {model}")  # fmt: skip
        _word_changes(review, robot_of)
        reviews.append(review)
    thresholds = _outliers(reviews, baseline, outlier_alpha)
    reviews.sort(key=lambda r: (-r.flagged, -r.evidence, r.robot_id))
    tested = sum(1 for r in reviews if math.isfinite(r.history.threshold))
    statements = [
        f"Changes: each robot's logs from its {baseline + 1}th on are tested against its own earlier logs, for a step "
        f"(payload, configuration) or a ramp (wear) starting within the last {window} logs.  A robot whose parameters "
        f"do not change is flagged with probability at most {alpha:g} over its whole history (Gaussian log-to-log "
        f"scatter; thresholds calibrated by seeded Monte Carlo and made conservative for small rates): about "
        f"{tested * alpha:.2g} false flags expected among these {tested} robots.  Scatter with heavier tails than "
        "Gaussian raises that rate; parameters correlated with each other lower it.",
        f"Sensitivity: under each robot, the smallest changes its tests flag at least half the time, from the "
        f"scatter of its first {baseline} logs: a step of each inertial parameter on its first log, and each wheel's "
        f"friction rising over {min(SENSITIVITY_RAMP_LOGS, window)} logs (its most sensitive parameter); smaller "
        "changes may pass unflagged.",
        f"Fleet comparison: each robot's mean over its first {baseline} logs against the mean and spread of the other "
        f"robots of the same robot file (Student's t); the probability that any robot of a model with Gaussian "
        f"unit-to-unit spread is said to stand out is at most {outlier_alpha:g} (Bonferroni; at least {MIN_FLEET} "
        "robots per model).",
    ]
    if repeats:
        statements.append(f"{repeats} rows of logs already in the table (the same content identified again with other "
                          "options) were left out: each log counts once.")  # fmt: skip
    if any(r.per_log for r in reviews):
        statements.append("Robots whose logs lack start times are ordered by log name and their rates are per log.")
    settings = {"baseline": baseline, "window": window, "alpha": alpha, "outlier_alpha": outlier_alpha}
    return FleetReview(reviews, settings, statements, thresholds)


def _wheel_friction(review: RobotReview, baseline: int) -> dict[str, tuple[float, np.ndarray, np.ndarray]]:
    """Each wheel's friction torque at its typical speed (:func:`~wmrid.fleets.changes.friction_at`): the
    median of the wheel's mean speeds over the robot's first ``baseline`` logs that have one (a table of schema 1,
    or logs all without speeds: none)."""
    out: dict[str, tuple[float, np.ndarray, np.ndarray]] = {}
    for name, fv, fd, speed, corr in _WHEEL_COLUMNS:
        speeds = [r.get(speed) for r in review.rows[:baseline]]
        known = [float(v) for v in speeds if v is not None and math.isfinite(v)]
        if not known:
            continue
        omega = float(np.median(known))
        (v_fv, s_fv), (v_fd, s_fd) = review.series(fv), review.series(fd)
        rho = np.array([r.get(corr) if r.get(corr) is not None else np.nan for r in review.rows], dtype=float)
        value, std = friction_at(omega, v_fv, v_fd, s_fv, s_fd, rho)
        out[name] = (omega, value, std)
    return out


def _sensitivity(review: RobotReview, baseline: int, window: int) -> tuple[dict[str, Any], str]:
    """The smallest changes the robot's tests flag at least half the time
    (:func:`~wmrid.fleets.changes.detectable`): each watched parameter's step on its first log and rise
    over :data:`SENSITIVITY_RAMP_LOGS` logs, from the sd of its first ``baseline`` logs (and no smaller than the
    size rule of :func:`~wmrid.fleets.changes.analyse_robot`), relative to their mean; and a sentence
    with the inertial steps and, per wheel, its most sensitive friction parameter."""
    h = review.history.threshold
    if not math.isfinite(h) or len(review.rows) <= baseline:
        return {}, ""
    ramp_logs = min(SENSITIVITY_RAMP_LOGS, window)
    k_step, k_ramp = detectable(h, baseline, 1, "step"), detectable(h, baseline, ramp_logs, "ramp")
    step: dict[str, float] = {}
    ramp: dict[str, float] = {}
    for name in review.watched:
        values, stds = review.series(name)
        base, base_std = values[:baseline], stds[:baseline]
        mean, sd = float(np.mean(base)), float(np.std(base, ddof=1))
        known = base_std[np.isfinite(base_std)]
        floor = 0.0 if name in WHEEL_FRICTION or not known.size else MIN_EFFECT_STDS * float(np.median(known))
        scale = abs(mean) if mean != 0 else math.inf
        step[name] = max(k_step * sd, floor) / scale
        ramp[name] = max(k_ramp * sd, floor) / scale
    inertial = ", ".join(f"{n} {100 * step[n]:.2g} %" for n in MONITORED[:4])
    wheels = []
    for wheel in ("right", "left"):
        names = [n for n in review.watched if WHEEL_OF.get(n) == wheel]
        best = min(names, key=lambda n: ramp[n])
        wheels.append(f"{100 * ramp[best]:.2g} % ({wheel} wheel, {best})")
    text = (f"smallest changes flagged at least half the time: a step on its first log of {inertial}; a friction rise "
            f"over {ramp_logs} logs of {' and '.join(wheels)}")  # fmt: skip
    return {"step": step, "ramp": ramp, "ramp_logs": ramp_logs}, text


def _pct(x: float) -> str:
    return f"{100 * x:+.1f} %" if math.isfinite(x) else "from 0"


def _word_changes(review: RobotReview, robot_of: Callable[[str], Any] | None) -> None:
    hist = review.history
    if hist.note:
        review.findings.append(hist.note)
    if hist.odd_logs:
        names = ", ".join(review.label_of(i) for i in hist.odd_logs)
        review.findings.append(
            f"odd log{'s' if len(hist.odd_logs) > 1 else ''} left out of the change test: {names} (beyond 3 std of "
            "the robot's earlier logs, the next logs back within it)"
        )
    for change in hist.changes:
        onset, alarm = review.label_of(change.onset), review.label_of(change.alarm)
        lag = _lag(review, change.onset, change.alarm)
        pending = " (on the robot's latest log: no later log confirms it yet)" if change.confirmed is None else ""
        if change.confirmed is False:
            pending = " (the logs after the alarm do not all agree)"
        inertial = [p for p in change.parameters if p not in FRICTION]
        friction = [p for p in change.parameters if p in FRICTION]
        if inertial:
            shifts = ", ".join(f"{p} {_pct(change.relative(p))}" for p in inertial)
            text = f"payload or configuration change from {onset} (flagged {alarm}{lag}): {shifts}"
            if friction:
                text += "; friction changed with it: " + ", ".join(
                    f"{review.describe(p)} {_pct(change.relative(p))}" for p in friction
                )
            review.payload = _payload(review, change, robot_of)
            if review.payload is not None:
                m, m_sd = review.payload["mass"]
                x, y = review.payload["x"][0], review.payload["y"][0]
                sd = f" ± {m_sd:.2g}" if m_sd is not None else ""
                text += (f"; payload ≈ {m:.3g}{sd} kg at x = {x:.3g} m, y = {y:.3g} m (against the robot's own "
                         "logs before the change; the ± is their scatter, not the model's error)")  # fmt: skip
            elif robot_of is not None:
                text += "; no payload estimate: the robot's r and b are unknown (give --robot or a robot column)"
            review.findings.append(text + pending)
            review.flags.append("payload or configuration change")
        else:
            wheels = sorted({WHEEL_OF[p] for p in friction})
            unit = "log" if review.per_log else "day"
            rising = [p for p in friction if change.relative(p) > 0]
            how = ", ".join(
                f"{review.describe(p)} {_pct(change.relative(p))}"
                + (f" ({100 * change.rate_per_day[p]:+.2g} %/{unit})" if change.kind == "ramp" else "")
                for p in friction
            )  # fmt: skip
            wheel_text = " and ".join(wheels) + (" wheel's" if len(wheels) == 1 else " wheels'")
            if rising and len(rising) == len(friction):
                verb = "rising" if change.kind == "ramp" else "up"
                review.findings.append(
                    f"wheel wear? {wheel_text} friction {verb} from {onset} (flagged {alarm}{lag}): {how}{pending}"
                )
                review.flags.append(f"wheel wear? ({' and '.join(wheels)})")
            else:
                review.findings.append(f"{wheel_text} friction changed from {onset} (flagged {alarm}{lag}): {how}"
                                       f"{pending}")  # fmt: skip
                review.flags.append(f"friction change ({' and '.join(wheels)})")


def _lag(review: RobotReview, onset: int, alarm: int) -> str:
    a, b = review.time_of(onset), review.time_of(alarm)
    if a is None or b is None:
        return f", {alarm - onset} logs later" if alarm > onset else ""
    days = (b - a).total_seconds() / 86400
    return (f", {days:.3g} day{'' if days == 1 else 's'} after") if alarm > onset else ""


def _payload(review: RobotReview, change: Any, robot_of: Callable[[str], Any] | None):
    """{mass, x, y, inertia: (value, standard error or None)} from the mean of the logs from the onset on against the
    mean of the robot's own logs before it (odd logs left out), when its r and b are known; the standard error
    from both means' log-to-log scatter by the delta method."""
    if robot_of is None:
        return None
    robot = robot_of(review.model)  # NO_MODEL: the report's --robot, if given
    if robot is None:
        return None
    r, b = robot.nominal.r, robot.nominal.b
    before = [change.before[n] for n in ("M11", "M12", "M22", "Vc")]
    names = ("M11", "M12", "M22", "Vc")
    odd = set(review.history.odd_logs)
    values = np.array([[row[n] for n in names] for row in review.rows])
    used = np.array([i not in odd for i in range(len(values))])
    before_logs = values[: change.onset][used[: change.onset]]
    after_logs = values[change.onset :][used[change.onset :]]
    before, after = before_logs.mean(axis=0), after_logs.mean(axis=0)
    med = payload_from_change(before, after, r, b)
    err = [None] * 4
    if len(before_logs) > 1 and len(after_logs) > 1:
        # delta method: the means' covariances (log-to-log scatter / logs) through central differences
        var = np.zeros(4)
        for mean, logs, which in ((before, before_logs, 0), (after, after_logs, 1)):
            jac = np.zeros((4, 4))
            for j in range(4):
                step = 1e-6 * max(abs(mean[j]), 1e-6)
                up, down = mean.copy(), mean.copy()
                up[j] += step
                down[j] -= step
                args_up = (up, after) if which == 0 else (before, up)
                args_down = (down, after) if which == 0 else (before, down)
                jac[:, j] = (payload_from_change(*args_up, r, b) - payload_from_change(*args_down, r, b)) / (2 * step)
            var += np.diag(jac @ (np.cov(logs.T) / len(logs)) @ jac.T)
        err = np.sqrt(np.clip(var, 0.0, None))
    return {n: (float(v), None if e is None else float(e)) for n, v, e in zip(PAYLOAD_NAMES, med, err, strict=True)}


def _outliers(reviews: list[RobotReview], baseline: int, alpha: float) -> dict[str, tuple[int, float]]:
    """Mark the robots that stand out among those of the same model; returns {model: (robots, threshold)}."""
    groups: dict[str, list[RobotReview]] = {}
    for rv in reviews:
        if len(rv.rows) >= 3:
            groups.setdefault(rv.model, []).append(rv)
    out = {}
    for model, members in groups.items():
        if len(members) < MIN_FLEET:
            continue
        levels = np.array([[np.mean([r[n] for r in rv.rows[:baseline]]) for n in MONITORED] for rv in members])
        z = leave_one_out_t(levels)
        h = outlier_threshold(alpha, len(members))
        out[model] = (len(members), h)
        for k, (rv, zr, lv) in enumerate(zip(members, z, levels, strict=True)):
            others = np.delete(levels, k, axis=0).mean(axis=0)
            rv.evidence = max(rv.evidence, float(np.max(np.abs(zr)) / h))
            beyond = [i for i in np.argsort(-np.abs(zr)) if abs(zr[i]) > h]
            if beyond:
                rv.outlier = {MONITORED[i]: float(zr[i]) for i in beyond}
                parts = ", ".join(f"{MONITORED[i]} {lv[i]:.4g} (the others' mean {others[i]:.4g}, t {zr[i]:+.1f})"
                                  for i in beyond)  # fmt: skip
                rv.findings.append(f"stands out from the {len(members)} robots of {model}: {parts}")
                rv.flags.append("stands out from the fleet")
    return out
