"""`faultledger token list` and `faultledger token revoke` (`token create` is in cli/web.py,
beside `http`); docs/http.md, "Auth". The token file is changed only by service.tokens, under
its lock; a running server follows it within seconds."""

from __future__ import annotations

import json
import shutil
from datetime import UTC, datetime
from pathlib import Path
from typing import Annotated, Any

import typer

from faultledger.cli.options import ConfigOption, JsonOption, fail, settings_for
from faultledger.cli.safe_text import printable
from faultledger.errors import FaultLedgerError
from faultledger.service.config import Settings, TokenEntry
from faultledger.service.tokens import UnknownTokenError, load_file, revoke

FileOption = Annotated[Path | None, typer.Option(
    "--file", metavar="FILE",
    help="Token file (default: the config's http.tokens_file, var/http-tokens.yaml).")]
PICKUP = "a running server {} within 2 s"
"""What `token create` and `token revoke` say of a running server (TokenWatcher polls 1/s)."""
MINUTE = "%Y-%m-%d %H:%M"
GAP = "  "


def token_file(settings: Settings, file: Path | None) -> Path:
    """The token file a `token` command works on: ``--file``, else the config's."""
    path = file or settings.http.tokens_file
    if path is None:
        fail("no token file: give --file or set http.tokens_file in the config")
    return path


def token_list(config: ConfigOption = None, file: FileOption = None,
               as_json: JsonOption = False) -> None:
    """List tokens: name, role, expiry, creation.

    Times in UTC; never a token or its hash. The token file's tokens, then the config's
    inline ones (http.tokens), marked *.
    """
    settings = settings_for(config)
    path = file or settings.http.tokens_file
    rows: list[tuple[TokenEntry, str]] = []
    try:
        if path is not None and path.exists():
            rows += [(entry, "file") for entry in load_file(path)]
    except FaultLedgerError as error:
        fail(str(error))
    rows += [(entry, "config") for entry in settings.http.tokens]
    now = datetime.now(UTC)
    if as_json:
        typer.echo(json.dumps([_json(entry, source, now) for entry, source in rows], indent=2))
        return
    where = str(path) if path is not None else "no token file"
    if not rows:
        typer.echo(printable(f"no tokens ({where}): the server is open to loopback clients"))
        return
    for line in table(rows, now, shutil.get_terminal_size((80, 24)).columns):
        typer.echo(printable(line))
    if any(source == "config" for _, source in rows):
        typer.echo("* in the config's http.tokens: edit the config to remove it")


def _json(entry: TokenEntry, source: str, now: datetime) -> dict[str, Any]:
    def iso(moment: datetime | None) -> str | None:
        return None if moment is None else moment.strftime("%Y-%m-%dT%H:%M:%SZ")

    return {"name": entry.name, "role": entry.role, "expires_at": iso(entry.expires_at),
            "expired": entry.expires_at is not None and now >= entry.expires_at,
            "created_at": iso(entry.created_at), "source": source}


def table(rows: list[tuple[TokenEntry, str]], now: datetime, width: int) -> list[str]:
    """NAME, ROLE, EXPIRES (UTC), CREATED (UTC) within ``width`` columns (at least 80 is
    assumed: names are at most 64): a name longer than its column stands on a line of its
    own, the rest of its row under it, so nothing is cut."""
    cells = []
    for entry, source in rows:
        if entry.expires_at is None:
            expires = "never"
        else:
            expires = entry.expires_at.strftime(MINUTE)
            if now >= entry.expires_at:
                expires += " (expired)"
        created = "-" if entry.created_at is None else entry.created_at.strftime(MINUTE)
        role = entry.role + ("*" if source == "config" else "")
        cells.append((entry.name, role, expires, created))
    header = ("NAME", "ROLE", "EXPIRES (UTC)", "CREATED (UTC)")
    widths = [max(len(row[i]) for row in [header, *cells]) for i in range(1, 4)]
    rest = sum(widths) + len(GAP) * 3
    name_width = max(len(header[0]), min(max(len(row[0]) for row in cells),
                                         max(width, 80) - rest))

    def line(row: tuple[str, str, str, str]) -> str:
        parts = [row[0].ljust(name_width)] + [cell.ljust(w) for cell, w in zip(
            row[1:], widths, strict=True)]
        return GAP.join(parts).rstrip()

    lines = [line(header)]
    for row in cells:
        if len(row[0]) > name_width:
            lines.append(row[0])
            lines.append(line(("", *row[1:])))
        else:
            lines.append(line(row))
    return lines


def token_revoke(
    name: Annotated[str, typer.Argument(metavar="NAME", help="The token's name (token list).")],
    config: ConfigOption = None, file: FileOption = None,
) -> None:
    """Revoke a token: its entry leaves the token file.

    A running server refuses it within 2 s, without a restart.
    """
    settings = settings_for(config)
    path = token_file(settings, file)
    try:
        entry = revoke(path, name)
    except UnknownTokenError as error:
        if any(inline.name == name for inline in settings.http.tokens):
            fail(f"token {name!r} is in the config's http.tokens, not in the token file "
                 f"{path}: remove it from the config (and restart the server)", 1)
        fail(str(error), 1)
    except FaultLedgerError as error:
        fail(str(error))
    typer.echo(printable(f"token {entry.name!r} ({entry.role}) revoked: removed from {path}; "
                         f"{PICKUP.format('refuses it')}"))
