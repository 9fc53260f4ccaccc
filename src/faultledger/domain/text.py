"""Showing text from outside (reporters, operators, publishers, files) to a person, literally.

Descriptions, source ids, actors, reasons, node names and error messages that quote input can
hold anything: terminal escape sequences (``\\x1b[2J``, OSC-8 links), carriage returns, bidi
overrides. ``printable`` makes such text inert and visible on one line, for every adapter
(terminal, log lines, HTML). Exports (JSON, CSV, JSON Lines) keep the exact text.
"""

from __future__ import annotations

import re
import unicodedata

_UNSAFE_CATEGORIES = frozenset({"Cc", "Cf", "Cs", "Zl", "Zp"})
"""Controls (C0, DEL, C1), format characters (bidi embeddings, overrides and isolates, marks,
zero-width characters, tag characters, BOM), lone surrogates, line and paragraph separators."""
_NAMED = {"\n": "\\n", "\r": "\\r", "\t": "\\t"}
_CANDIDATE = re.compile(r"[^\x20-\x7e]")
"""Everything outside printable ASCII is looked at; the common all-ASCII text is one scan."""


def _escape(match: re.Match[str]) -> str:
    char = match.group()
    if unicodedata.category(char) not in _UNSAFE_CATEGORIES:
        return char
    named = _NAMED.get(char)
    if named is not None:
        return named
    point = ord(char)
    if point <= 0xFF:
        return f"\\x{point:02x}"
    if point <= 0xFFFF:
        return f"\\u{point:04x}"
    return f"\\U{point:08x}"


def printable(text: object) -> str:
    """``text`` as a single line safe for a terminal or a page: every control, format and
    separator character (ESC, CR, LF, TAB, DEL, C1, U+202E, U+2028, ...) becomes a visible
    Python-style escape (``\\x1b``, ``\\n``, ``\\u202e``); everything else is unchanged,
    backslashes included. Not markup-escaped: pass the result as a ``Text`` (see ``cell``)."""
    return _CANDIDATE.sub(_escape, text if isinstance(text, str) else str(text))
