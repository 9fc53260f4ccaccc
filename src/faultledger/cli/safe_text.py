"""Showing text from outside (reporters, operators, publishers, files) to a person, literally.

Descriptions, source ids, actors, reasons, node names and error messages that quote input can
hold anything: rich markup (``[/]``), terminal escape sequences (``\\x1b[2J``, OSC-8 links),
carriage returns, bidi overrides. ``printable`` makes such text inert and visible on one line;
``cell`` wraps it in a ``rich.text.Text`` so rich never reads it as markup. Exports (JSON, CSV,
JSON Lines) keep the exact text; this is only for what a person reads.
"""

from __future__ import annotations

import re
import unicodedata

from rich.text import Text

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


def cell(text: object, style: str | None = None) -> Text:
    """A table cell (or any rich renderable) showing ``text`` literally: never parsed as
    markup, never carrying a control character."""
    return Text(printable(text), style=style or "")
