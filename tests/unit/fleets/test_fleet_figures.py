"""The fleet review's figures (wmrid.fleets.figures) at the edges: robot names XML forbids, logs dated years 1 and
9999, a robot with a single log; each read back from its SVG."""

from __future__ import annotations

import datetime as dt
import math
import re

import numpy as np
import pytest
import svgutil

from wmrid.fleets.changes import MONITORED, RobotHistory
from wmrid.fleets.figures import build_evidence_figure, build_robot_figure
from wmrid.fleets.review import FleetReview, RobotReview
from wmrid.reporting.svg_axes import text_width

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


def _with_wheels(robot: RobotReview) -> RobotReview:
    """The robot with each wheel's friction at its typical speed: a fifth column of panels, narrower ones."""
    n = len(robot.rows)
    robot.wheel_friction = {f"Fw{k}": (4.0, np.linspace(0.1, 0.2, n), np.full(n, 0.01)) for k in (1, 2)}
    return robot


def _x_labels(root) -> list[list[str]]:
    """The x tick labels of the bottom row's panels (the figure's panels share x: only those label it)."""
    drawn = svgutil.panels(root)
    return [svgutil.tick_labels(p, "x") for p in drawn[len(drawn) // 2 :]]


def _inside_the_figure(root) -> None:
    """Every text (its estimated width, centred or anchored) within the figure's width."""
    width = float(root.get("width"))
    for t in root.iter(f"{NS}text"):
        if t.get("transform"):
            continue
        x = float(t.get("x") or t.find(f"{NS}tspan").get("x"))
        w = text_width(svgutil.text_of(t), float(t.get("font-size")))
        anchor = t.get("text-anchor", "start")
        lo = x - (w / 2 if anchor == "middle" else w if anchor == "end" else 0.0)
        assert lo >= -0.5, svgutil.text_of(t)
        assert lo + w <= width + 0.5, svgutil.text_of(t)


def test_a_robot_with_logs_dated_years_1_and_9999_has_ticks():
    """Two logs 9999 years apart in panels 1.5 inches wide: the largest step (2000 years) gave four ticks where
    three fit, and there was no fallback, so no x tick at all; the points sat on the limits, half clipped."""
    robot = _with_wheels(_robot("R1", [dt.datetime(1, 1, 1), dt.datetime(9999, 12, 31)]))
    fig = build_robot_figure(robot)
    root = svgutil.parse(fig.to_svg())
    for labels in _x_labels(root):
        assert len(labels) >= 2
        assert all(re.fullmatch(r"\d{4}(-\d\d-\d\d)?", label) for label in labels), labels
    _inside_the_figure(root)
    for panel in svgutil.panels(root):  # the points (dots) stand clear of the panel's left and right edges
        left, _, right, _ = svgutil.frame(panel)
        dots = [p for p in svgutil.data(panel).iter(f"{NS}path") if p.get("d", "").count("a") == 4]
        starts = [float(v) for d in dots for v in re.findall(r"M(-?[\d.]+),", d.get("d"))]  # each dot's left
        assert len(starts) == 2
        assert all(left + 2.0 <= x and x + 4.0 <= right - 2.0 for x in starts)  # 4 px across: whole, and clear


def test_a_robot_with_a_single_log_has_its_band_and_whole_log_numbers():
    """One log without a start time: the ±2σ band the caption promises (a band needs two points: none was drawn),
    and the logs' axis labelled 0 (it was −0.4 ... 0.4)."""
    fig = build_robot_figure(_robot("R1", [None]))
    root = svgutil.parse(fig.to_svg())
    drawn = svgutil.panels(root)
    for panel in drawn:
        (bar,) = [r for r in svgutil.data(panel).iter(f"{NS}rect") if r.get("fill-opacity") == "0.25"]
        dot = next(p for p in svgutil.data(panel).iter(f"{NS}path") if p.get("d", "").count("a") == 2)
        x, y = (float(v) for v in re.match(r"M(-?[\d.]+),(-?[\d.]+)", dot.get("d")).groups())
        assert float(bar.get("x")) + float(bar.get("width")) / 2 == pytest.approx(x + 2.0, abs=0.01)  # the dot's
        assert float(bar.get("y")) + float(bar.get("height")) / 2 == pytest.approx(y, abs=0.01)  # centre: ±2σ
        assert float(bar.get("width")) == 6.0
        assert float(bar.get("height")) > 0
    assert _x_labels(root) == [["0", "log"]] * 4  # the tick labels, then the axis' label
    fig = build_robot_figure(_robot("R1", [None] * 3))
    assert _x_labels(svgutil.parse(fig.to_svg())) == [["0", "1", "2", "log"]] * 4
