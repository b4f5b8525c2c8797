"""The fleet report as one call: :func:`fleet_report` reviews a ``wmrid fleet`` table (changes across each robot's
logs, robots that stand out, a ranking) and :func:`write_fleet_report` writes it as HTML, Markdown or JSON by the
file's suffix.  ``wmrid fleet-report`` is these two functions with its flags translated.

Imports inside functions: start-up time (a front door: ``import wmrid`` and each function load only what that
function uses).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from wmrid.core.errors import UsageError, WmridError, option
from wmrid.fleets.rendering import FleetReport, build_fleet_report

if TYPE_CHECKING:
    from wmrid.model.robot import Robot

__all__ = ["fleet_report", "write_fleet_report"]


def check_settings(baseline: int, window: int, alpha: float, outlier_alpha: float) -> None:
    """Refuse settings no table can make right, before the table is read."""
    from wmrid.fleets.changes import MIN_BASELINE

    if isinstance(baseline, bool) or not isinstance(baseline, int) or baseline < MIN_BASELINE:
        raise UsageError(f"{option('baseline')} must be a whole number of logs >= {MIN_BASELINE}, got {baseline!r}")
    if isinstance(window, bool) or not isinstance(window, int) or window < 1:
        raise UsageError(f"{option('window')} must be a whole number of logs >= 1, got {window!r}")
    for name, value in (("alpha", alpha), ("outlier_alpha", outlier_alpha)):
        if not (isinstance(value, (int, float)) and 1e-9 <= value <= 0.2):
            raise UsageError(f"{option(name)} must be a probability in [1e-09, 0.2], got {value!r}")


def _robot_loader(robot: str | None) -> Callable[[str], Robot | None]:
    """name -> Robot or None (a robot column that no longer loads gives no payload estimate, not an error)."""
    from wmrid.api.inputs import load_robot
    from wmrid.fleets.review import NO_MODEL

    cache: dict[str, Robot | None] = {}

    def robot_of(name: str) -> Robot | None:
        key = robot if name == NO_MODEL else name
        if key is None:
            return None
        if key not in cache:
            try:
                loaded = load_robot(key)
                cache[key] = loaded if loaded.physical else None
            except (WmridError, OSError):
                cache[key] = None
        return cache[key]

    return robot_of


def fleet_report(
    table: str | os.PathLike[str] | list[dict[str, Any]],
    *,
    robot: str | None = None,
    baseline: int = 10,
    window: int = 30,
    alpha: float = 0.001,
    outlier_alpha: float = 0.001,
    figures: bool = True,
    command: str | None = None,
) -> FleetReport:
    """The review of a fleet table: changes across each robot's logs, robots that stand out, a ranking.

    Parameters
    ----------
    table
        A path to a ``wmrid fleet`` Parquet table, or its rows.
    robot
        The robot (file or built-in name) of the rows without one: its r and b turn a change of M and V_c into a
        payload estimate.
    baseline
        Each robot's first ``baseline`` logs are its own reference.
    window
        A step or ramp starting within the last ``window`` logs is tested.
    alpha
        The probability of flagging a robot whose parameters do not change, over its whole history.
    outlier_alpha
        The probability that any robot of a model with Gaussian unit-to-unit spread is said to stand out.
    figures
        Build the figures (what HTML and Markdown show).
    command
        The command line that made the review, for its reproducibility block (None: ``wmrid.fleet_report(...)``).

    Returns
    -------
    FleetReport
        The review; :func:`write_fleet_report` writes it.

    Raises
    ------
    UsageError
        A setting out of its range, or a table without rows.
    """
    from wmrid.fleets.changes import MONITORED
    from wmrid.fleets.review import review_fleet
    from wmrid.fleets.table import ADDED_IN_2, read_arrow

    check_settings(baseline, window, alpha, outlier_alpha)
    name = os.fspath(table) if isinstance(table, (str, os.PathLike)) else "rows"
    if isinstance(table, (str, os.PathLike)):  # only the columns the review reads: a row of ~20 values, not ~60
        columns = ["robot_id", "log", "robot", "start_time", "error", *MONITORED, *(f"{n}_std" for n in MONITORED),
                   *ADDED_IN_2]  # fmt: skip
        rows = read_arrow(name).select(columns).to_pylist()
    else:
        rows = list(table)
    if not rows:
        raise UsageError(f"{name}: the fleet table has no rows")
    review = review_fleet(rows, baseline=baseline, window=window, alpha=alpha, outlier_alpha=outlier_alpha,
                          robot_of=_robot_loader(robot))  # fmt: skip
    rep = build_fleet_report(review, rows, name, figures=figures)
    from wmrid.api.reporting import provenance_block
    from wmrid.io.digest import file_digests

    options = {"robot": robot, "baseline": baseline, "window": window, "alpha": alpha, "outlier_alpha": outlier_alpha}
    inputs = file_digests(name) if isinstance(table, (str, os.PathLike)) else []
    rep.provenance = provenance_block(command or "wmrid.fleet_report(...)", options, inputs)
    return rep


def write_fleet_report(rep: FleetReport, output: str | os.PathLike[str], *, force: bool = False) -> None:
    """Write a fleet review as a self-contained HTML page, Markdown or JSON, atomically.

    Parameters
    ----------
    rep
        The review (:func:`fleet_report`).
    output
        The output's path; its suffix names the format: .html or .htm, .md, or .json.
    force
        Overwrite an existing file.

    Raises
    ------
    UsageError
        ``output`` has none of the suffixes above.
    OutputExistsError
        ``output`` exists and ``force`` is not given.
    """
    from wmrid.api.reporting import write_by_suffix
    from wmrid.fleets.rendering import to_html, to_json_dict, to_markdown

    write_by_suffix(output, rep, to_html, to_markdown, to_json_dict, force=force)
