"""A table of a report (:class:`ReportTable`): its header, its rows of cells, and the statement said above it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class ReportTable:
    """header : the column titles.  rows : the cells, one list per row (text, or numbers already formatted).
    statement : said above the table (the payload's), or None."""

    header: list[str]
    rows: list[list[Any]]
    statement: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """The table as the report's JSON holds it: {"header", "rows"} and the statement when there is one."""
        out: dict[str, Any] = {"header": self.header, "rows": self.rows}
        if self.statement is not None:
            out["statement"] = self.statement
        return out

    @property
    def numeric(self) -> tuple[int, ...]:
        """The columns a terminal right-aligns: every one but the first and the unit."""
        return tuple(i for i, h in enumerate(self.header) if i and h != "unit")
