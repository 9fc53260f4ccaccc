"""Showing text from outside to a person in the terminal: ``printable`` (domain/text.py) makes
it inert and visible on one line; ``cell`` wraps it in a ``rich.text.Text`` so rich never reads
it as markup (``[/]``).
"""

from __future__ import annotations

from rich.text import Text

from faultledger.domain.text import printable

__all__ = ["cell", "printable"]

def cell(text: object, style: str | None = None) -> Text:
    """A table cell (or any rich renderable) showing ``text`` literally: never parsed as
    markup, never carrying a control character."""
    return Text(printable(text), style=style or "")
