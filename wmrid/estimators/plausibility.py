"""Units a log can be in by mistake, found before any number is trusted (:func:`units_check`).

A unit mistake does not make the estimate noisy; it makes it confidently wrong.  Read in log units (speed
eta_log = s eta, time t_log = q t, effort tau_log = e tau), the model of Eq. (20) is still linear in the same
parameters, only rescaled:

    M' = e q M / s,   Vc' = e Vc / s^2,   Fv' = e Fv / s,   Fd' = e Fd   (a caster's drag as Fd),

so rpm read as rad/s (s = 60/2pi) gives M 9.55 times too small and Vc 91 times too small, milliseconds read as
seconds (q = 1000) M 1000 times too large and Vc unchanged, and PWM counts read as N m every parameter scaled
alike.  Two kinds of evidence are used:

* the signals alone: a log sampled slower than MIN_RATE_HZ (no wheel dynamics is seen at 1 Hz; a time column in
  milliseconds makes a 1 kHz log look like that), a rim speed no wheeled robot drives (over MAX_RIM_SPEED with the
  robot's wheel radius, MAX_WHEEL_SPEED rad/s without one), efforts in "N m" that are all whole numbers up to at
  least PWM_MIN (PWM counts);
* the robot file: the estimate against the robot's nominal (and CAD) base parameters, in logarithms.  A unit
  mistake moves log M11, log M22, log Vc, log Fv, log Fd along the fixed direction above; when the estimate is
  further than MISMATCH from the robot's and one unit's direction brings it within CONSISTENT, that unit is named.

What is found is a list of findings, each one sentence naming the suspected unit and the flag that fixes it; a
finding marks every parameter flagged ("do not trust this std": the value itself is in the wrong unit) and makes
the verdict say so first (:mod:`wmrid.estimators.verdict`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from wmrid.core.wheel_log import WHOLE_EFFORTS_NOTE

#: Slower than this a log cannot show wheel dynamics (mechanical time constants of 0.05-1 s): its time column is
#: suspected of a unit mistake.
MIN_RATE_HZ = 2.0
#: A plausible logging rate, Hz, for the time unit that would explain a slow log.
PLAUSIBLE_RATES_HZ = (5.0, 20_000.0)
#: m/s at the rim no differential-drive robot drives (54 km/h; the fastest field robots reach about 10 m/s).
MAX_RIM_SPEED = 15.0
#: m/s, a typical top rim speed of a wheeled robot: of the units that would bring implausible speeds within
#: MAX_RIM_SPEED, the one whose top speed is nearest it (in ratio) is named first.
TYPICAL_RIM_SPEED = 1.5
#: rad/s at a wheel beyond which, without the robot's radius, the speeds are suspected (about 2900 rpm).
MAX_WHEEL_SPEED = 300.0
#: rad/s at a wheel above which, without a robot file to check them, the speeds are said to be fast (a 5 cm wheel at
#: 2.5 m/s; rpm read as rad/s reaches it at 480 rpm): a warning, not a doubt.
FAST_WHEEL_SPEED = 50.0
#: Efforts labelled N m that are all whole numbers up to at least this are taken for PWM counts.
PWM_MIN = 20.0
#: The estimate is called far from the robot file when its log-ratios have an rms above log(MISMATCH)...
MISMATCH = 4.0
#: ... and a unit explains it when, undone, the rms falls below log(CONSISTENT) (a robot file is rarely off by 2x).
CONSISTENT = 2.0
#: A parameter takes part in the comparison when its std is below this fraction of its value.
USABLE_STD = 0.5

#: Exponents (speed s, time q, effort e) of each compared quantity's scale under a unit mistake.
_EXPONENTS = {"M": (-1, 1, 1), "Vc": (-2, 0, 1), "Fv": (-1, 0, 1), "Fd": (0, 0, 1)}


def _kind(name: str) -> str | None:
    if name in ("M11", "M22"):
        return "M"
    if name == "Vc":
        return "Vc"
    if name in ("Fv1", "Fv2"):
        return "Fv"
    if name in ("Fd1", "Fd2"):
        return "Fd"
    return None


def speed_units(r: float | None) -> list[tuple[str, float, str]]:
    """(what, s, fix): speeds logged in another unit and read as rad/s, eta_log = s eta."""
    out = [
        ("rpm", 60.0 / (2.0 * math.pi), "--speed-unit rpm"),
        ("deg/s", 180.0 / math.pi, "--speed-unit deg/s"),
        ("revolutions per second", 1.0 / (2.0 * math.pi), "convert them to rad/s (x 2 pi)"),
    ]
    if r is not None and r > 0 and abs(math.log(r)) > math.log(CONSISTENT):
        out.append(("m/s at the rim", r, "--speed-unit m/s"))
    return out


TIME_UNITS = (
    ("milliseconds", 1e3, "--time-unit ms"),
    ("microseconds", 1e6, "--time-unit us"),
    ("seconds read as milliseconds", 1e-3, "--time-unit s"),
)


def signal_findings(
    scales: dict[str, Any], r: float | None = None, notes: tuple[str, ...] = ()
) -> list[dict[str, Any]]:
    """Unit doubts the signals show by themselves (``scales``: :meth:`wmrid.estimators.observer.survey.Survey.scales`;
    ``r`` m: the robot's wheel radius, or None; ``notes``: the log's reading notes, which say when an effort topic held
    whole numbers before it was put on the speed stamps).  Each: {"quantity": "time"|"speed"|"effort", "unit", "fix",
    "text", "doubt"}; "columns" when a wheel's speed and effort fit far better exchanged (``scales["swapped"]``)."""
    out: list[dict[str, Any]] = []
    rate = scales.get("rate_hz")
    duration = scales.get("duration_s") or 0.0
    if rate is not None and 0 < rate < MIN_RATE_HZ:
        step = 1.0 / rate
        guess = next(
            ((what, q, fix) for what, q, fix in TIME_UNITS[:2] if PLAUSIBLE_RATES_HZ[0] <= rate * q
             <= PLAUSIBLE_RATES_HZ[1]),
            None,
        )  # fmt: skip
        text = (
            f"the log steps {step:.3g} s at a time ({rate:.3g} Hz over {duration:.6g} s): no wheel dynamics shows at "
            "that rate"
        )
        if guess is not None:
            what, q, fix = guess
            text += f"; a time column in {what} would make it {rate * q:.4g} Hz over {duration / q:.4g} s: give {fix}"
            out.append({"quantity": "time", "unit": what, "fix": fix, "text": text, "doubt": True})
        else:
            out.append({"quantity": "time", "unit": None, "fix": "--time-unit", "text": text + "; check its time unit",
                        "doubt": True})  # fmt: skip
    speed = max(scales.get("speed_max") or [0.0])
    limit = MAX_RIM_SPEED / r if r else MAX_WHEEL_SPEED
    if speed > limit:
        where = f" ({speed * r:.3g} m/s at the rim of the robot's {r:g} m wheels)" if r else ""
        fits = [(what, s, fix) for what, s, fix in speed_units(r)[:2] if speed / s <= limit]
        if r:  # the unit whose top rim speed is most typical first
            fits.sort(key=lambda f: abs(math.log(speed / f[1] * r / TYPICAL_RIM_SPEED)))
        if fits:
            said = [
                f"in {what} they would reach {speed / s:.4g} rad/s" + (f" ({speed / s * r:.3g} m/s)" if r else "")
                + f": give {fix}"
                for what, s, fix in fits
            ]  # fmt: skip
            text = f"the wheel speeds reach {speed:.4g} rad/s{where}, faster than a wheeled robot drives; " + (
                "; or ".join(said)
            )
            out.append({"quantity": "speed", "unit": fits[0][0], "fix": fits[0][2], "text": text, "doubt": True})
        else:
            text = (
                f"the wheel speeds reach {speed:.4g} rad/s{where}, faster than a wheeled robot drives; check their unit"
            )
            out.append({"quantity": "speed", "unit": None, "fix": "--speed-unit", "text": text, "doubt": True})
    elif not r and speed > FAST_WHEEL_SPEED:
        text = (
            f"the wheel speeds reach {speed:.4g} rad/s ({speed * 60 / (2 * math.pi):.3g} rpm), fast for a wheel; if "
            "they were logged in rpm give --speed-unit rpm (a robot file with the wheel radius lets wmrid check them)"
        )
        out.append({"quantity": "speed", "unit": "rpm", "fix": "--speed-unit rpm", "text": text, "doubt": False})
    swapped = [w for w, flag in zip(("right", "left"), scales.get("swapped") or (), strict=False) if flag]
    if swapped:
        which = (
            "both wheels' speeds and efforts fit"
            if len(swapped) == 2
            else f"the {swapped[0]} wheel's speed and effort fit"
        )
        text = f"{which} the model far better exchanged: the columns (or topics) look swapped; check --columns"
        out.append({"quantity": "columns", "unit": None, "fix": "--columns", "text": text, "doubt": True})
    effort = max(scales.get("effort_max") or [0.0])
    whole = scales.get("effort_whole") or any(WHOLE_EFFORTS_NOTE in note for note in notes)
    if scales.get("effort_unit", "N m") == "N m" and whole and effort >= PWM_MIN:
        text = (
            f"the efforts are all whole numbers up to {effort:.6g}: PWM counts (or another command), not N m; give "
            "--effort pwm (the parameters are then in PWM units), or the unit they are in"
        )
        out.append({"quantity": "effort", "unit": "PWM counts", "fix": "--effort pwm", "text": text, "doubt": True})
    return out


def _log_ratios(parameters: dict[str, tuple[float, float]], reference: dict[str, float]) -> list[tuple[str, float]]:
    """(name, log(estimate / reference)) of the compared quantities both give with one sign, the estimate to better
    than USABLE_STD."""
    out = []
    for name, (value, std) in parameters.items():
        kind = _kind(name)
        ref = reference.get(name)
        if kind is None or ref is None or not (math.isfinite(value) and math.isfinite(ref)):
            continue
        if value == 0 or ref == 0 or (value > 0) != (ref > 0):
            continue
        if not (math.isfinite(std) and std < USABLE_STD * abs(value)):
            continue
        out.append((name, math.log(value / ref)))
    return out


def _rms(values: list[float]) -> float:
    return math.sqrt(sum(v * v for v in values) / len(values)) if values else 0.0


def robot_findings(
    parameters: dict[str, tuple[float, float]],
    references: list[tuple[str, dict[str, float]]],
    r: float | None,
    effort_free: bool = False,
) -> tuple[list[dict[str, Any]], dict[str, Any] | None]:
    """Unit doubts from the estimate against the robot file's values.

    ``references``: (label, named base parameters with M11, M12, M22) pairs, nominal then CAD.  ``effort_free``:
    the efforts are not in N m (a current, a PWM command), so every comparison allows a free effort scale and only
    the ratios between parameters (Vc/M, Fv/M, ...) can show a speed or time unit.  Returns (findings as
    :func:`signal_findings`'s, the comparison record or None when nothing could be compared).  The record:
    {"reference", "rms_factor" (the typical factor between the estimate and the robot's, after the free effort
    scale when ``effort_free``), "compared" (names)}.  An estimate that only a uniform scale explains is the
    robot file not describing this robot or efforts not in N m: said, not a doubt (nothing tells them apart).
    """
    best_record = None
    best: list[dict[str, Any]] = []
    for label, ref in references:
        ratios = _log_ratios(parameters, ref)
        if not ratios:
            continue
        kinds = {_kind(n) for n, _ in ratios}
        if effort_free and len(kinds) < 2:
            continue  # one kind of parameter: its scale is the effort's, nothing to test
        shift = sum(y for _, y in ratios) / len(ratios) if effort_free else 0.0
        ratios = [(n, y - shift) for n, y in ratios]
        rms0 = _rms([y for _, y in ratios])
        record = {"reference": label, "rms_factor": math.exp(rms0), "compared": [n for n, _ in ratios]}
        if best_record is not None and record["rms_factor"] >= best_record["rms_factor"]:
            continue
        best_record = record
        best = []
        if rms0 <= math.log(MISMATCH):
            continue
        fits: list[tuple[float, dict[str, Any]]] = []
        candidates = [("speed", what, s, fix, (math.log(s), 0.0, 0.0)) for what, s, fix in speed_units(r)]
        candidates += [("time", what, q, fix, (0.0, math.log(q), 0.0)) for what, q, fix in TIME_UNITS]
        for quantity, what, factor, fix, (ls, lq, _) in candidates:
            residual = [y - (np.dot(_EXPONENTS[_kind(n)], (ls, lq, 0.0))) for n, y in ratios]
            if effort_free:
                mean = sum(residual) / len(residual)
                residual = [v - mean for v in residual]
            rms = _rms(residual)
            if rms <= math.log(CONSISTENT):
                fits.append((rms, {"quantity": quantity, "unit": what, "fix": fix, "factor": factor}))
        if len(kinds) >= 2 and not effort_free:  # a free scale: only two kinds tell it from a speed or time unit
            le = sum(y for _, y in ratios) / len(ratios)
            rms = _rms([y - le for _, y in ratios])
            if rms <= math.log(CONSISTENT) and abs(le) > math.log(CONSISTENT):
                fits.append((rms, {"quantity": "effort", "unit": None, "fix": "--effort", "factor": math.exp(le)}))
        fits.sort(key=lambda f: f[0])
        shown = ", ".join(f"{n} {math.exp(y):.3g}x" for n, y in ratios)
        scaled = " beyond one common scale (the efforts are not in N m)" if effort_free else ""
        lead = f"the estimate is {math.exp(rms0):.3g} times off the robot file's {label} values{scaled} ({shown})"
        if not fits:
            best = [{
                "quantity": "robot", "unit": None, "fix": None, "doubt": False,
                "text": f"{lead}, more than a robot file is off: check the log's units (--speed-unit, --time-unit, "
                "--effort) and the robot file",
            }]  # fmt: skip
            continue
        top = fits[0][1]
        if top["quantity"] == "effort":
            best = [{
                "quantity": "robot", "unit": None, "fix": "--effort", "doubt": False,
                "text": f"{lead}, every parameter by about the same factor ({top['factor']:.3g}): the robot file does "
                "not describe this robot, or the efforts are not in N m (a PWM command or a current: give --effort)",
            }]  # fmt: skip
            continue
        guesses = [
            f"{fit['quantity']}s in {fit['unit']} (a factor {fit['factor']:.4g}: give {fit['fix']})"
            for _, fit in fits[:2]
            if fit["quantity"] != "effort"
        ]
        if len(kinds) < 2 and not effort_free:
            guesses.append("efforts not in N m (give --effort)")
        best = [{
            "quantity": top["quantity"], "unit": top["unit"], "fix": top["fix"], "doubt": True,
            "text": f"{lead}, as a unit mistake would make it: " + "; or ".join(guesses),
        }]  # fmt: skip
    return best, best_record


def units_check(
    parameters: dict[str, tuple[float, float]],
    scales: dict[str, Any] | None,
    references: list[tuple[str, dict[str, float]]],
    r: float | None,
    notes: tuple[str, ...] | list[str] = (),
    effort_free: bool = False,
) -> dict[str, Any]:
    """The units check of a result: {"findings": [...], "robot": comparison record or None, "doubt": bool}.

    ``parameters``: the reported (value, std) by name; ``scales``: the log's (``log_info["scales"]``, None when
    unknown); ``references``: (label, base parameters by name) of the robot file; ``r`` m: its wheel radius;
    ``effort_free``: the efforts are not in N m, so the comparison allows them any scale (:func:`robot_findings`).
    ``doubt``: some finding's ``doubt`` (it names a unit that explains the numbers, or the signals cannot be in the
    units they are read in): every parameter is then flagged.  A finding without doubt (fast speeds without a robot
    file to check them, an estimate far from the robot file that no unit explains) is a warning only.
    """
    findings = signal_findings(scales, r, tuple(notes)) if scales else []
    from_robot, record = robot_findings(parameters, references, r, effort_free) if references else ([], None)
    for finding in from_robot:
        same = [f for f in findings if f["quantity"] == finding["quantity"]]
        if any(f["doubt"] for f in same):
            continue  # the signals already named it
        findings = [f for f in findings if f not in same] + [finding]
    findings.sort(key=lambda f: not f["doubt"])
    doubt = any(f["doubt"] for f in findings)
    return {"findings": findings, "robot": record, "doubt": doubt}
