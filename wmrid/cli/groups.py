"""Groups of flags declared once: an options dataclass of the library turned into Typer parameters, shared by every
command that takes it (:func:`takes`).

A command names the object it wants as a parameter (``log_options: LogOptions``); :func:`takes` replaces that
parameter in the signature Typer reads by one flag per field of the dataclass (its type, help and panel from the
field's ``Annotated`` alias in :mod:`wmrid.cli.options`, its default the dataclass's own), and calls the command with
the object made from the flags' values, checked once as it is made.  So ``identify``, ``report``, ``compare``,
``fleet``, ``monitor`` and ``live`` offer the same log and observer flags, and a new field reaches them all.
"""

from __future__ import annotations

import copy
import functools
import inspect
from collections.abc import Callable
from dataclasses import MISSING, dataclass, field, fields, replace
from enum import Enum
from typing import Annotated, Any, TypeVar, get_args

from wmrid.api.inputs import LogOptions
from wmrid.cli.options import (
    AlignOpt,
    AlphaOpt,
    BoxWidthOpt,
    ColumnsOpt,
    ControlRateOpt,
    CutoffOpt,
    DelayOpt,
    EfficiencyOpt,
    EffortOpt,
    EffortTopicOpt,
    EffortUnitOpt,
    FlipEffortOpt,
    ForgettingOpt,
    FormOpt,
    FrictionOpt,
    GearRatioOpt,
    KOpt,
    LeftJointOpt,
    MirrorLeftOpt,
    PayloadOpt,
    RightJointOpt,
    SpeedUnitOpt,
    TimeSourceOpt,
    TimeUnitOpt,
    TopicOpt,
    TorqueConstantOpt,
    TorqueHoldOpt,
    VelocityFromOpt,
    VelocityTopicOpt,
    WeightedOpt,
    WheelRadiusOpt,
)
from wmrid.estimators.options import MethodOptions, ObserverOptions

F = TypeVar("F", bound=Callable[..., Any])


@dataclass(frozen=True)
class OptionGroup:
    """The flags of one options dataclass.

    keyword : the command's parameter that receives the object.  options : the dataclass.  flags : field name -> the
    flag's ``Annotated`` alias; every field is a flag or in ``internal`` (set by the library, never by a flag).
    renamed : field name -> the flag's parameter name where they differ (``cutoff_hz`` is ``--cutoff``).
    """

    keyword: str
    options: type
    flags: dict[str, Any]
    internal: frozenset[str] = frozenset()
    renamed: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        names = {f.name for f in fields(self.options)}
        loose = names - set(self.flags) - self.internal
        if loose or set(self.flags) - names:
            raise TypeError(f"{self.options.__name__}: fields without a flag {sorted(loose)}, or flags without a field")

    def parameters(self) -> list[inspect.Parameter]:
        """The flags as keyword parameters, defaults from the dataclass (an Enum flag's default as its member)."""
        out = []
        for f in fields(self.options):
            if f.name in self.internal:
                continue
            name, alias = self.renamed.get(f.name, f.name), self.flags[f.name]
            default = f.default if f.default is not MISSING else f.default_factory()  # type: ignore[misc]
            kind = get_args(alias)[0]
            if isinstance(kind, type) and issubclass(kind, Enum) and default is not None:
                default = kind(default)
            out.append(inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=default, annotation=alias))
        return out

    def make(self, values: dict[str, Any]) -> Any:
        """The options object of the flags' values (``values`` by parameter name; Enum members as their values)."""
        given = {}
        for field_name in self.flags:
            value = values[self.renamed.get(field_name, field_name)]
            given[field_name] = value.value if isinstance(value, Enum) else value
        return self.options(**given)

    @property
    def names(self) -> tuple[str, ...]:
        """The flags' parameter names."""
        return tuple(self.renamed.get(name, name) for name in self.flags)

    def adapted(
        self, *, without: tuple[str, ...] = (), texts: dict[str, str] | None = None, panel: str | None = None
    ) -> OptionGroup:
        """This group for one command: ``without`` fields left out (the object gets their defaults), ``texts``: help
        by field for what the flag means there, every flag in ``panel``."""
        flags = {}
        for field_name, alias in self.flags.items():
            if field_name in without:
                continue
            text = (texts or {}).get(field_name)
            if text is not None or panel is not None:
                kind, info = get_args(alias)[:2]
                info = copy.copy(info)
                if text is not None:
                    info.help = text
                if panel is not None:
                    info.rich_help_panel = panel
                alias = Annotated[kind, info]
            flags[field_name] = alias
        return replace(self, flags=flags, internal=self.internal | frozenset(without))


LOG_FLAGS = OptionGroup(
    "log_options",
    LogOptions,
    {
        "columns": ColumnsOpt,
        "time_unit": TimeUnitOpt,
        "topic": TopicOpt,
        "velocity_topic": VelocityTopicOpt,
        "effort_topic": EffortTopicOpt,
        "right_joint": RightJointOpt,
        "left_joint": LeftJointOpt,
        "time_source": TimeSourceOpt,
        "align": AlignOpt,
        "velocity_from": VelocityFromOpt,
        "speed_unit": SpeedUnitOpt,
        "wheel_radius": WheelRadiusOpt,
        "effort": EffortOpt,
        "effort_unit": EffortUnitOpt,
        "torque_constant": TorqueConstantOpt,
        "gear_ratio": GearRatioOpt,
        "efficiency": EfficiencyOpt,
        "mirror_left": MirrorLeftOpt,
        "flip_effort": FlipEffortOpt,
    },
)

OBSERVER_FLAGS = OptionGroup(
    "observer",
    ObserverOptions,
    {
        "form": FormOpt,
        "k": KOpt,
        "alpha": AlphaOpt,
        "box_width": BoxWidthOpt,
        "torque_hold": TorqueHoldOpt,
        "control_rate": ControlRateOpt,
        "delay": DelayOpt,
        "friction": FrictionOpt,
        "payload": PayloadOpt,
    },
    internal=frozenset({"max_history"}),
)

FIT_FLAGS = OptionGroup(
    "fit",
    MethodOptions,
    {
        "cutoff_hz": CutoffOpt,
        "weighted": WeightedOpt,
        "forgetting": ForgettingOpt,
    },
    renamed={"cutoff_hz": "cutoff"},
)


def takes(*groups: OptionGroup) -> Callable[[F], F]:
    """Decorate a command (beneath ``@app.command``): each group's ``keyword`` parameter becomes the group's flags
    in the signature Typer reads, and the command receives the object made from them."""

    def decorate(command: F) -> F:
        signature = inspect.signature(command)
        hints = _evaluated(command, {g.keyword for g in groups})
        own: list[inspect.Parameter] = []
        for p in signature.parameters.values():
            group = next((g for g in groups if g.keyword == p.name), None)
            if group is None:
                own.append(p.replace(annotation=hints[p.name]))
            else:
                own.extend(group.parameters())
        taken = {name for g in groups for name in g.names}
        clash = taken & {p.name for p in signature.parameters.values()}
        if clash:
            raise TypeError(f"{command.__name__}: parameters {sorted(clash)} are flags of a group it takes")
        # keyword-only parameters after positional-or-keyword ones with defaults: Typer reads the names, not the kinds
        own = [p.replace(kind=inspect.Parameter.KEYWORD_ONLY) for p in own]

        @functools.wraps(command)
        def run(**values: Any) -> Any:
            for group in groups:
                values[group.keyword] = group.make({name: values.pop(name) for name in group.names})
            return command(**values)

        run.__signature__ = signature.replace(parameters=own)  # type: ignore[attr-defined]
        run.__annotations__ = {p.name: p.annotation for p in own}
        if signature.return_annotation is not inspect.Signature.empty:
            run.__annotations__["return"] = hints.get("return", Any)
        del run.__wrapped__  # type: ignore[attr-defined]  (Typer must read the new signature, not the command's)
        return run  # type: ignore[return-value]

    return decorate


def _evaluated(command: Callable[..., Any], skip: set[str]) -> dict[str, Any]:
    """The command's annotations evaluated in its module (``from __future__ import annotations`` leaves text), the
    groups' keywords left out (their types may be imported for type checking only)."""
    namespace = getattr(command, "__globals__", {})
    out = {}
    for name, text in command.__annotations__.items():
        if name in skip:
            continue
        out[name] = eval(text, namespace) if isinstance(text, str) else text
    return out
