"""The fleet review's figures (wmrid.fleets.figures) at the edges: robot names XML forbids, logs dated years 1 and
9999, a robot with a single log; each read back from its SVG."""

from __future__ import annotations

import datetime as dt
import math

import svgutil

from wmrid.fleets.changes import MONITORED, RobotHistory
from wmrid.fleets.figures import build_evidence_figure
from wmrid.fleets.review import FleetReview, RobotReview

NS = svgutil.NS


def _robot(robot_id: str, times: list[dt.datetime | None], evidence: float = 0.5) -> RobotReview:
    """A robot whose logs (at ``times``; None: without a start time) rise by 0.1 in every parameter, σ 0.05."""
    rows = [
        {"log": f"log{i}", "start_time": t, **{n: 1.0 + 0.1 * i for n in MONITORED},
         **{f"{n}_std": 0.05 for n in MONITORED}}
        for i, t in enumerate(times)
    ]  # fmt: skip
    robot = RobotReview(robot_id, "diffdrive", rows, 0, RobotHistory(len(rows), math.inf))
    robot.evidence = evidence
    return robot


def test_the_evidence_figure_of_robots_named_with_characters_xml_forbids():
    names = ["nc\uffff", "R\ufffe2", "R\ud8003", "R\x014"]
    review = FleetReview([_robot(n, [None, None], evidence=2.0 - k) for k, n in enumerate(names)], {}, [], {})
    root = svgutil.parse(build_evidence_figure(review).to_svg())  # encodes, and is well-formed XML
    (panel,) = svgutil.panels(root)
    assert svgutil.tick_labels(panel, "y")[::-1] == ["nc", "R2", "R3", "R4"]
