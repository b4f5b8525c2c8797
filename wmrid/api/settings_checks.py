"""identify's settings checked before any log is read: what each method models (:data:`CASTER_METHODS`,
:data:`LOAD_METHODS`, :data:`CONTROL_RATE_METHODS`), the friction model settled, an option refused where it would be
ignored, the settings read from their names (:func:`settings_from`) and said back (:func:`settings_given`).

Used by :mod:`wmrid.api.identification` (which re-exports them), the report and the fleet.
"""

from __future__ import annotations

import math
import os
from typing import Any

from wmrid.core.errors import UsageError, option
from wmrid.estimators.options import (
    FIT_NAMES,
    FRICTION_CHOICES,
    OBSERVER_NAMES,
    SETTING_NAMES,
    MethodOptions,
    ObserverOptions,
    check_control_rate_value,
)
from wmrid.model.robot import Robot

#: Methods that model caster drag (``friction="wheel+caster"``); output error only with the casters' positions.
CASTER_METHODS = ("observer", "idim", "iv", "rls", "oe")
#: Methods that model a caster drag that follows the load (``friction="wheel+caster+load"``).  IDIM, IV and RLS fit
#: it too (the observer's closed-loop check runs them on its form), but on the light AMR's reversing MuJoCo log their
#: std came out too small with it (Fv2 2.9 % off at z = 5.2, where the caster model's std covered its 3.3 %), so
#: they are not offered it yet.
LOAD_METHODS = ("observer",)
#: Methods that model a controller faster than the log (``control_rate``).
CONTROL_RATE_METHODS = ("observer", "idim", "iv", "rls")


def _refuse_unmodelled(
    name: str, value: Any, methods: tuple[str, ...], validating: bool, supported: tuple[str, ...]
) -> None:
    """UsageError when an option would be ignored: by a method outside ``supported``, or by the validation
    predictor."""
    others = [m for m in methods if m not in supported]
    given = option(name, value) if name != "control_rate" else option(name)
    if others:
        names = supported[0] if len(supported) == 1 else f"{', '.join(supported[:-1])} and {supported[-1]}"
        raise UsageError(
            f"{given} is modelled by the {names} only, not by {', '.join(others)} yet; drop it or "
            f"use {option('method', supported[0])}"
        )
    if validating:
        raise UsageError(f"{given} is not modelled by the {option('validate')} predictor yet; validate without it")


def friction_model(friction: str, methods: tuple[str, ...], validating: bool, robot: Robot | None) -> str:
    """The friction model to identify with.

    ``auto`` falls back to ``wheel`` where the *method* cannot model caster drag: another method, or output error
    without the casters' positions (it simulates the drag, which needs its direction).  An explicit
    ``wheel+caster`` there is refused.  ``validating`` changes nothing here: an option that only adds output never
    changes the estimate (a model whose drag the validation predictor cannot simulate is validated without a fit,
    and the validation says why: :func:`wmrid.api.identification.validate`).
    """
    if friction not in FRICTION_CHOICES:
        raise UsageError(f"{option('friction')} must be one of {', '.join(FRICTION_CHOICES)}, got {friction!r}")
    positions = robot is not None and bool(robot.casters)
    if friction == "wheel+caster+load":
        _refuse_unmodelled("friction", friction, methods, False, LOAD_METHODS)
        if not positions:
            raise UsageError(
                f"{option('friction', 'wheel+caster+load')} needs the casters' positions: give {option('robot')} with "
                "[[caster]] tables"
            )
    if friction == "wheel+caster":
        _refuse_unmodelled("friction", friction, methods, False, CASTER_METHODS)
        if "oe" in methods and not positions:
            raise UsageError(
                f"{option('friction', 'wheel+caster')} with {option('method', 'oe')} needs "
                f"the casters' positions to simulate their drag: give {option('robot')} with [[caster]] tables, or "
                "drop the option"
            )
    if friction == "auto" and (any(m not in CASTER_METHODS for m in methods) or ("oe" in methods and not positions)):
        return "wheel"
    return friction


def check_control_rate(control_rate: float | None, methods: tuple[str, ...], validating: bool) -> None:
    """A controller rate is modelled by the observer, IDIM and RLS (output error and the validation predictor hold
    each logged effort over the whole step): refuse it where it would be ignored."""
    if control_rate is not None:
        check_control_rate_value(control_rate)  # a frequency > 0 first, then where it is modelled
        _refuse_unmodelled("control_rate", control_rate, methods, validating, CONTROL_RATE_METHODS)


def settings_from(flat: dict[str, Any]) -> tuple[str, ObserverOptions, MethodOptions]:
    """(method, observer options, classical methods' options) from settings by name (:data:`SETTING_NAMES`; None:
    the default; ``delay`` also as text), each checked once as its object is made; another name is refused."""
    unknown = sorted(set(flat) - set(SETTING_NAMES))
    if unknown:
        raise UsageError(f"unknown setting {unknown[0]!r}; the settings are {', '.join(SETTING_NAMES)}")
    given = {k: v for k, v in flat.items() if v is not None}
    observer = ObserverOptions(**{k: v for k, v in given.items() if k in OBSERVER_NAMES})
    fit = MethodOptions(**{FIT_NAMES[k]: v for k, v in given.items() if k in FIT_NAMES})
    return str(given.get("method", "auto")), observer, fit


def settings_given(method: str, observer: ObserverOptions, fit: MethodOptions) -> dict[str, Any]:
    """The settings that differ from their defaults, by name (:data:`SETTING_NAMES`): what a report's provenance
    records."""
    out: dict[str, Any] = {} if method == "auto" else {"method": method}
    plain_observer, plain_fit = ObserverOptions(), MethodOptions()
    out.update({k: getattr(observer, k) for k in OBSERVER_NAMES if getattr(observer, k) != getattr(plain_observer, k)})
    out.update({k: getattr(fit, f) for k, f in FIT_NAMES.items() if getattr(fit, f) != getattr(plain_fit, f)})
    return out


def no_two_stdin(log: Any, validate_log: Any, what: str) -> None:
    """UsageError when both logs are standard input ("-"; several files of one recording never are)."""
    if all(isinstance(p, (str, os.PathLike)) and os.fspath(p) == "-" for p in (log, validate_log)):
        raise UsageError(f"{what} and {option('validate')} cannot both be standard input; give one of them as a file")


def check_validation(log: Any, other: Any, observer: ObserverOptions, methods: tuple[str, ...], what: str) -> None:
    """Before anything is read: refuse what ``--validate OTHER`` cannot do with these settings (a controller rate,
    which its predictor does not model; ``log`` and ``other`` both standard input).  Nothing when ``other`` is None."""
    if other is None:
        return
    check_control_rate(observer.control_rate, tuple("observer" if m == "auto" else m for m in methods), True)
    no_two_stdin(log, other, what)


def check_rotor_inertia(rotor_inertia: float | None) -> None:
    """Refuse a rotor inertia that is not a finite number >= 0 kg m^2 (None: none)."""
    if rotor_inertia is not None and not (math.isfinite(rotor_inertia) and rotor_inertia >= 0):
        raise UsageError(f"{option('rotor_inertia')} must be a finite number >= 0 (kg m^2), got {rotor_inertia!r}")
