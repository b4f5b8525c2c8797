"""The style of wmrid's SVG figures (:mod:`wmrid.reporting.svg`): font sizes, colours (the Tableau 10 palette
C0..C9, greys, a diverging red-blue scale), dash patterns, and how numbers and text are written into SVG."""

from __future__ import annotations

import math

#: The Tableau 10 palette, named C0 ... C9 as the figures have always called them: right wheel C0 (blue), left
#: wheel C1 (orange).
TAB10 = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf")
_NAMED = {"k": "#000000", "black": "#000000", "white": "#ffffff", "w": "#ffffff", "none": "none"}
#: Dash patterns (dash, gap, ...), in units of the line's width.
_DASHES = {"--": (3.7, 1.6), ":": (1.0, 1.65), "-.": (6.4, 1.6, 1.0, 1.6)}
#: Font sizes, px: tick labels and axis labels, legends and small labels, panel titles.
FONT, SMALL, TITLE = 13.0, 11.5, 14.5
#: Tick length and the padding between a panel's parts, px.
TICK, PAD = 4.0, 3.0
#: Stands for the id prefix of a figure's elements until the figure's content gives it (never in escaped text).
ID_PLACEHOLDER = "<id>"


def colour(name: str) -> str:
    """An SVG colour from a short name: ``C0`` .. ``C9`` (:data:`TAB10`), ``k``, ``white``, a grey level
    ``"0.45"`` (0 black .. 1 white) or ``#rrggbb`` (kept)."""
    if name.startswith("#") or name in ("none",):
        return name
    if len(name) == 2 and name[0] == "C" and name[1].isdigit():
        return TAB10[int(name[1])]
    if name in _NAMED:
        return _NAMED[name]
    level = round(255 * float(name))
    return f"#{level:02x}{level:02x}{level:02x}"


#: ColorBrewer's diverging red-blue, reversed (RdBu_r): -1 dark blue, 0 near white, +1 dark red; 11 stops.
RDBU_R = ("#053061", "#2166ac", "#4393c3", "#92c5de", "#d1e5f0", "#f7f7f7", "#fddbc7", "#f4a582", "#d6604d",
          "#b2182b", "#67001f")  # fmt: skip
#: The colour of a cell without a value (a grey, 75 % white).
MISSING = "#bfbfbf"


def diverging(value: float, lo: float = -1.0, hi: float = 1.0) -> str:
    """The colour of ``value`` on :data:`RDBU_R` from ``lo`` (blue) to ``hi`` (red), interpolated linearly between
    its stops and clipped at the ends; :data:`MISSING` when ``value`` is not finite."""
    if not math.isfinite(value):
        return MISSING
    s = min(max((value - lo) / (hi - lo), 0.0), 1.0) * (len(RDBU_R) - 1)
    k = min(int(s), len(RDBU_R) - 2)
    a, b = RDBU_R[k], RDBU_R[k + 1]
    mix = [round(int(a[i : i + 2], 16) * (k + 1 - s) + int(b[i : i + 2], 16) * (s - k)) for i in (1, 3, 5)]
    return "#" + "".join(f"{c:02x}" for c in mix)


def luminance(hex_colour: str) -> float:
    """Perceived brightness (0 black .. 1 white) of ``#rrggbb``: 0.299 r + 0.587 g + 0.114 b."""
    r, g, b = (int(hex_colour[i : i + 2], 16) / 255.0 for i in (1, 3, 5))
    return 0.299 * r + 0.587 * g + 0.114 * b


def num(value: float) -> str:
    """A coordinate rounded to 2 decimals, without trailing zeros (``12.5``, ``3``, never ``-0``)."""
    text = f"{round(float(value), 2) + 0.0:.2f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def escape(text: str) -> str:
    """``text`` for an XML text node or attribute (``&``, ``<``, ``>``, quotes escaped; control characters dropped)."""
    text = "".join(c for c in text if c >= " " or c in "\n\t")
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace('"', "&quot;")


def stroke(color: str, width: float, dash: str | None = None, opacity: float = 1.0) -> str:
    """The stroke attributes of a line: colour, width (px), dash (``--``, ``:``, ``-.``) and opacity."""
    out = f'stroke="{colour(color)}" stroke-width="{num(width)}"'
    if dash in _DASHES:
        out += f' stroke-dasharray="{",".join(num(d * width) for d in _DASHES[dash])}"'
    return out + (f' stroke-opacity="{num(opacity)}"' if opacity < 1.0 else "")
