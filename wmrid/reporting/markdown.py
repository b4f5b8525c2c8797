"""Markdown that says what an input holds and nothing more: every string that came from an input (a topic, joint or
file name, a saved result's source, notes and warnings, a robot id, a command line) is escaped before it joins
wmrid's own Markdown, as the HTML reports escape it with :func:`html.escape` (issue 30).

* ``<``, ``>`` and ``&`` become character references, so no raw HTML (``<script>``, ``<img onerror=…>``, ``<!--``)
  and no autolink reaches the page; a Markdown viewer shows the characters themselves.
* Every line break (``\\n``, ``\\r``, form feed, U+2028 …) and other control character becomes a space, so a name
  can neither start a heading, a list, a quote or a table row nor end the line it is on.
* The characters that make links, images, emphasis, code and table cells (``\\ ` * _ [ ] | ~``) are backslash
  escaped, and so is a character that would start a block where the string starts a line (``#``, ``>``, ``-``,
  ``+``, ``=``, ``1.``).

:func:`text` escapes prose, :func:`code` shows a string as code (a backtick code span when that is safe as it
stands, else ``<code>`` around the escaped text), :func:`table` writes a table with every cell escaped.
"""

from __future__ import annotations

import re
from typing import Any

#: Line breaks and control characters: each becomes a space.
_BREAKS = re.compile(r"[\x00-\x1f\x7f-\x9f\u2028\u2029]")
#: What a backslash makes literal in CommonMark (the ASCII punctuation that has a meaning in running text).
_SPECIAL = re.compile(r"([\\`*_\[\]|~])")
#: A start of a line that would open a block: a heading, a quote, a list item, a setext underline, a thematic break.
_BLOCK_START = re.compile(r"^(#|>|-|\+|=|\d{1,9}(?=[.)]))")


def text(value: Any, start: bool = True) -> str:
    """``value`` as Markdown text that renders as the characters it holds, on one line; ``start``: it may begin a
    line or a list item (so a leading ``#``, ``-`` … is escaped too; a table cell or the middle of a sentence needs
    not)."""
    out = _BREAKS.sub(" ", str(value)).strip()
    out = out.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    out = _SPECIAL.sub(r"\\\1", out)
    match = _BLOCK_START.match(out) if start else None
    if match is not None:
        head = match.group(1)
        out = (head + "\\" + out[len(head) :]) if head[0].isdigit() else "\\" + out
    return out


def code(value: Any) -> str:
    """``value`` shown as code: a backtick code span when it holds no backtick, no markup character a reader of the
    file could mistake for HTML and no line break; else the escaped text in ``<code>``."""
    raw = str(value)
    if raw and not re.search(r"[`<>&]", raw) and not _BREAKS.search(raw):
        return f"`{raw}`"
    return f"<code>{text(raw, False)}</code>"


def table(header: list[Any], rows: list[list[Any]]) -> str:
    """A pipe table; each cell escaped by :func:`text` (``|`` inside a cell is ``\\|``)."""
    lines = ["| " + " | ".join(text(h, False) for h in header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(text(c, False) for c in row) + " |" for row in rows]
    return "\n".join(lines)
