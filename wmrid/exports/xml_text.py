"""Text for the XML exports: comments that stay comments whatever the input names hold."""

from __future__ import annotations

import re

from wmrid.core.xml_chars import XML_FORBIDDEN


def xml_comment(text: str) -> str:
    """An XML comment holding ``text``: characters XML forbids dropped, no "--" inside (every "-" followed by another
    gets a space after it, so "---" stays legal too) and none at the end (it would make "--->")."""
    clean = XML_FORBIDDEN.sub("", text)
    clean = re.sub(r"-(?=-)", "- ", clean)
    if clean.endswith("-"):
        clean += " "
    return f"<!-- {clean} -->"


def xml_attribute(text: str) -> str:
    """``text`` for a double-quoted XML attribute value."""
    clean = XML_FORBIDDEN.sub("", text)
    return clean.replace("&", "&amp;").replace('"', "&quot;").replace("<", "&lt;").replace(">", "&gt;")
