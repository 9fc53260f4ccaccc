"""HTTP bearer tokens: issued once, stored only as SHA-256 hashes (docs/http.md, "Auth").

A token is 32 random bytes (URL-safe base64) after a ``flt_`` prefix, so a leaked one is easy
to recognise in a log or a repository scan. Tokens are high-entropy, so a plain SHA-256 is
enough (no slow password hash is needed), and comparing hashes takes constant time.
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

import yaml
from pydantic import BaseModel, ConfigDict, Field

from faultledger.errors import ConfigError
from faultledger.service import config
from faultledger.service.config import HttpSettings, TokenEntry
from faultledger.service.output_files import write_output

PREFIX = "flt_"
TOKEN_FILE_MODE = 0o600


class Role(StrEnum):
    VIEWER = "viewer"
    """Reads: faults, history, statistics, the dashboard, the stream, metrics."""
    REPORTER = "reporter"
    """Posts reports and nothing else (a PLC gateway, a script)."""
    OPERATOR = "operator"
    """Reads, reports, and clears faults."""
    ADMIN = "admin"
    """Everything, including verify."""


class Permission(StrEnum):
    READ = "read"
    REPORT = "report"
    CLEAR = "clear"
    ADMINISTER = "administer"


GRANTS: dict[Role, frozenset[Permission]] = {
    Role.VIEWER: frozenset({Permission.READ}),
    Role.REPORTER: frozenset({Permission.REPORT}),
    Role.OPERATOR: frozenset({Permission.READ, Permission.REPORT, Permission.CLEAR}),
    Role.ADMIN: frozenset(Permission),
}


@dataclass(frozen=True, slots=True)
class Principal:
    """Who made a request: the token's name (the actor of its changes) and role."""

    name: str
    role: Role

    def may(self, permission: Permission) -> bool:
        return permission in GRANTS[self.role]


def digest(token: str) -> str:
    return hashlib.sha256(token.encode("utf-8", "surrogatepass")).hexdigest()


def new_token() -> str:
    return PREFIX + secrets.token_urlsafe(32)


class TokenFile(BaseModel):
    model_config = ConfigDict(extra="forbid")

    tokens: list[TokenEntry] = Field(default_factory=list)


def load_file(path: Path) -> list[TokenEntry]:
    return config.load_model(path, TokenFile, "token file").tokens


def configured(settings: HttpSettings) -> list[TokenEntry]:
    """The config's tokens plus the token file's (when it exists); names must be unique."""
    entries = list(settings.tokens)
    if settings.tokens_file is not None and settings.tokens_file.exists():
        entries.extend(load_file(settings.tokens_file))
    names = [entry.name for entry in entries]
    doubled = sorted({name for name in names if names.count(name) > 1})
    if doubled:
        raise ConfigError(f"token names must be unique; given more than once: {doubled}")
    return entries


class TokenBook:
    """Looks a presented bearer token up among the configured hashes."""

    def __init__(self, entries: list[TokenEntry]) -> None:
        self._entries = [(entry.sha256, Principal(entry.name, Role(entry.role)))
                         for entry in entries]

    def __bool__(self) -> bool:
        return bool(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def find(self, token: str) -> Principal | None:
        presented = digest(token)
        found = None
        for stored, principal in self._entries:  # no early exit: timing says nothing
            if hmac.compare_digest(stored, presented):
                found = principal
        return found


def issue(path: Path, name: str, role: Role) -> str:
    """Add a new token for ``name`` to the token file (created 0600) and return the token,
    which is shown once and stored nowhere."""
    entries = load_file(path) if path.exists() else []
    if any(entry.name == name for entry in entries):
        raise ConfigError(f"a token named {name!r} exists in {path}; choose another name or "
                          "remove that entry first")
    token = new_token()
    entry = TokenEntry(name=name, role=role.value, sha256=digest(token))
    entries.append(entry)
    text = yaml.safe_dump({"tokens": [e.model_dump() for e in entries]}, sort_keys=False)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_output(path, "# faultledger HTTP tokens (SHA-256 only); `faultledger token create`\n"
                 + text, force=True, mode=TOKEN_FILE_MODE)
    return token
