"""The characters XML 1.0 forbids, shared by every writer of XML text (the SVG figures, the robot exports)."""

from __future__ import annotations

import re

#: Characters XML 1.0 does not allow anywhere (its ``Char`` production): controls other than tab, newline and
#: carriage return; lone surrogates (nor can UTF-8 encode them); U+FFFE and U+FFFF.
XML_FORBIDDEN = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]")
