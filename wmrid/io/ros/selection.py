"""Which topics and joints of a recording hold the wheel signals (:class:`TopicSelection`), checked once.  No decoder is
loaded here, so that reading a CSV or Parquet log loads none."""

from __future__ import annotations

from dataclasses import dataclass

from wmrid.core.choices import AlignRule, TimeSource, VelocityFrom, values
from wmrid.core.errors import UsageError, option

TIME_SOURCES = values(TimeSource)
ALIGN_RULES = values(AlignRule)
VELOCITY_FROM = values(VelocityFrom)


@dataclass(frozen=True)
class TopicSelection:
    """Which topics and joints hold the wheel signals, and how to put them on one time base."""

    topic: str | None = None
    velocity_topic: str | None = None
    effort_topic: str | None = None
    right_joint: str | None = None
    left_joint: str | None = None
    time_source: str = "auto"
    align: str = "linear"
    velocity_from: str = "auto"

    def __post_init__(self) -> None:
        if self.time_source not in TIME_SOURCES:
            raise UsageError(
                f"{option('time_source')} must be one of {', '.join(TIME_SOURCES)}, got {self.time_source!r}"
            )
        if self.align not in ALIGN_RULES:
            raise UsageError(f"{option('align')} must be one of {', '.join(ALIGN_RULES)}, got {self.align!r}")
        if self.velocity_from not in VELOCITY_FROM:
            raise UsageError(
                f"{option('velocity_from')} must be one of {', '.join(VELOCITY_FROM)}, got {self.velocity_from!r}"
            )
        if self.topic and (self.velocity_topic or self.effort_topic):
            raise UsageError(
                f"give either {option('topic')}, or {option('velocity_topic')} and {option('effort_topic')}, not both"
            )
