"""Reading wmrid's SVG figures back in tests (a helper module, not a test module): the document parsed by
``xml.etree.ElementTree``, its panels (``<g class="panel">``), their lines, texts and legends."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

NS = "{http://www.w3.org/2000/svg}"


def parse(svg: bytes) -> ET.Element:
    """The root ``<svg>`` of a figure's bytes (well-formed XML, or ParseError)."""
    root = ET.fromstring(svg)
    assert root.tag == f"{NS}svg"
    return root


def panels(root: ET.Element) -> list[ET.Element]:
    """The figure's panels, in drawing order."""
    return root.findall(f"{NS}g[@class='panel']")


def data(panel: ET.Element) -> ET.Element:
    """A panel's clipped group: what it draws from its data."""
    (group,) = [g for g in panel.findall(f"{NS}g") if g.get("clip-path")]
    return group


def polylines(element: ET.Element) -> list[ET.Element]:
    return element.findall(f".//{NS}polyline")


def points(polyline: ET.Element) -> np.ndarray:
    """(n, 2) px of a polyline's single ``points`` attribute."""
    return np.array([[float(v) for v in p.split(",")] for p in polyline.get("points", "").split()])


def text_of(element: ET.Element) -> str:
    """A ``<text>``'s lines joined by newlines."""
    spans = element.findall(f"{NS}tspan")
    return "\n".join(s.text or "" for s in spans) if spans else element.text or ""


def texts(element: ET.Element) -> list[str]:
    """Every text under ``element``, in document order."""
    return [text_of(t) for t in element.iter(f"{NS}text")]


def legend_texts(element: ET.Element) -> list[str]:
    """The labels of every legend under ``element`` (in a panel's corner, or in rows below the panels)."""
    return [t for g in element.iter(f"{NS}g") if g.get("class") == "legend" for t in texts(g)]


def frame(panel: ET.Element) -> tuple[float, float, float, float]:
    """(left, top, right, bottom) px of a panel's frame."""
    rect = next(r for r in panel.findall(f"{NS}rect") if r.get("stroke") == "#000000")
    x, y, w, h = (float(rect.get(k, "0")) for k in ("x", "y", "width", "height"))
    return x, y, x + w, y + h


def tick_labels(panel: ET.Element, axis: str) -> list[str]:
    """The labels of a panel's x ticks (below its frame, in one row) or y ticks (left of it, anchored at their end)."""
    left, top, right, bottom = frame(panel)
    out = []
    for t in panel.findall(f"{NS}text"):
        if t.get("transform"):
            continue  # a y label
        x, y = float(t.get("x") or t.find(f"{NS}tspan").get("x")), float(t.get("y") or t.find(f"{NS}tspan").get("y"))
        if axis == "x" and top < y and bottom < y < bottom + 30 and left - 1 <= x <= right + 1:
            out.append(text_of(t))
        if axis == "y" and x < left and t.get("text-anchor") == "end":
            out.append(text_of(t))
    return out
