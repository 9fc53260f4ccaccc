"""HTTP bearer tokens: issued once, stored only as SHA-256 hashes (docs/http.md, "Auth").

A token is 32 random bytes (URL-safe base64) after a ``flt_`` prefix, so a leaked one is easy
to recognise in a log or a repository scan. Tokens are high-entropy, so a plain SHA-256 is
enough (no slow password hash is needed), and comparing hashes takes constant time.

The token file is changed only under an exclusive ``flock`` of ``<file>.lock`` beside it (read,
change, write), and written whole to a temporary file that replaces it in one step: concurrent
``token create`` / ``token revoke`` runs never lose each other's entries, and a reader (the
server's ``TokenWatcher``) never sees half a file. A running server notices a changed file
within about a second (``TokenWatcher``): a revoked token is refused, a new one works.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import hmac
import logging
import os
import re
import secrets
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from enum import StrEnum
from pathlib import Path

import yaml
from pydantic import BaseModel, ConfigDict, Field

from faultledger.domain.fleet import robot_id_error
from faultledger.errors import ConfigError, FaultLedgerError, Reason
from faultledger.service import config
from faultledger.service.config import (
    TOKEN_NAME_PATTERN,
    TOKEN_NAME_RULE,
    HttpSettings,
    TokenEntry,
)
from faultledger.service.output_files import write_output

log = logging.getLogger(__name__)

PREFIX = "flt_"
TOKEN_FILE_MODE = 0o600
HEADER = "# faultledger HTTP tokens (SHA-256 only); `faultledger token create`\n"
WATCH_INTERVAL_SEC = 1.0
"""How often a running server looks at the token file (one ``stat``)."""
MAX_LIFETIME = timedelta(days=36_500)
_DURATION = re.compile(r"^\s*(\d{1,9})\s*([smhd])\s*$")
_UNITS = {"s": "seconds", "m": "minutes", "h": "hours", "d": "days"}


class Role(StrEnum):
    VIEWER = "viewer"
    """Reads: faults, history, statistics, the dashboard, the stream, metrics."""
    REPORTER = "reporter"
    """Posts reports and nothing else (a PLC gateway, a script)."""
    OPERATOR = "operator"
    """Reads, reports, clears, acknowledges and shelves faults."""
    ADMIN = "admin"
    """Everything, including verify."""
    ROBOT = "robot"
    """Pushes its own log to a fleet central, and nothing else: its name is the robot_id of
    the only logs it may push (docs/fleet.md)."""


class Permission(StrEnum):
    READ = "read"
    REPORT = "report"
    CLEAR = "clear"
    ACKNOWLEDGE = "acknowledge"
    """Acknowledge, shelve and unshelve (the operator's day)."""
    ADMINISTER = "administer"
    PUSH = "push"


GRANTS: dict[Role, frozenset[Permission]] = {
    Role.VIEWER: frozenset({Permission.READ}),
    Role.REPORTER: frozenset({Permission.REPORT}),
    Role.OPERATOR: frozenset({Permission.READ, Permission.REPORT, Permission.CLEAR,
                              Permission.ACKNOWLEDGE}),
    Role.ADMIN: frozenset(Permission),
    Role.ROBOT: frozenset({Permission.PUSH}),
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


class UnknownTokenError(FaultLedgerError):
    """``token revoke`` of a name the token file does not have."""

    reason = Reason.NOT_FOUND


def check_name(name: str) -> str:
    """``name`` when it is a valid token name, else a ``ConfigError`` naming the rule."""
    if re.fullmatch(TOKEN_NAME_PATTERN, name) is None:
        raise ConfigError(f"invalid token name {name!r}: a name is {TOKEN_NAME_RULE}")
    return name


def check_role(text: str) -> Role:
    try:
        return Role(text.strip().lower())
    except ValueError:
        raise ConfigError(f"invalid role {text!r}: a role is one of "
                          f"{', '.join(role.value for role in Role)}") from None


def parse_lifetime(text: str) -> timedelta:
    """``30d``, ``12h``, ``90m``, ``45s``: a positive number and one unit."""
    found = _DURATION.match(text)
    if found is None or int(found.group(1)) == 0:
        raise ConfigError(f"invalid expiry {text!r}: give a positive whole number and a "
                          "unit s, m, h or d (45s, 90m, 12h, 30d)")
    lifetime = timedelta(**{_UNITS[found.group(2)]: int(found.group(1))})
    if lifetime > MAX_LIFETIME:
        raise ConfigError(f"invalid expiry {text!r}: at most {MAX_LIFETIME.days}d")
    return lifetime


def utc_text(moment: datetime) -> str:
    """``2026-11-20 10:00:00 UTC``: how messages and tables name a token's times."""
    return moment.astimezone(UTC).strftime("%Y-%m-%d %H:%M:%S UTC")


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


@dataclass(frozen=True, slots=True)
class Holder:
    """The token a request presented: who holds it, and until when it is valid."""

    principal: Principal
    expires_at: datetime | None

    def expired(self, now: datetime) -> bool:
        return self.expires_at is not None and now >= self.expires_at


class TokenBook:
    """Looks a presented bearer token up among the configured hashes. Expired tokens count
    (a server whose tokens all expired still needs one; it never falls open)."""

    def __init__(self, entries: list[TokenEntry]) -> None:
        self._entries = [(entry.sha256, Holder(Principal(entry.name, Role(entry.role)),
                                               entry.expires_at))
                         for entry in entries]

    def __bool__(self) -> bool:
        return bool(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def find(self, token: str) -> Holder | None:
        presented = digest(token)
        found = None
        for stored, holder in self._entries:  # no early exit: timing says nothing
            if hmac.compare_digest(stored, presented):
                found = holder
        return found


@contextlib.contextmanager
def locked(path: Path) -> Iterator[None]:
    """An exclusive ``flock`` of ``<path>.lock`` (created 0600 beside the token file) for one
    read-change-write of the token file; other ``token`` commands wait for it."""
    lock = path.with_name(path.name + ".lock")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(lock, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0)
                     | getattr(os, "O_CLOEXEC", 0), TOKEN_FILE_MODE)
    except OSError as error:
        raise ConfigError(f"cannot lock the token file ({lock}): "
                          f"{error.strerror or error}") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the lock


def _save(path: Path, entries: list[TokenEntry]) -> None:
    data = {"tokens": [entry.model_dump(mode="json", exclude_none=True) for entry in entries]}
    write_output(path, HEADER + yaml.safe_dump(data, sort_keys=False), force=True,
                 mode=TOKEN_FILE_MODE)


def issue(path: Path, name: str, role: Role, lifetime: timedelta | None = None,
          now: datetime | None = None) -> tuple[str, TokenEntry]:
    """Add a new token for ``name`` to the token file (created 0600) and return the token,
    which is shown once and stored nowhere, with its entry."""
    check_name(name)
    if role is Role.ROBOT:
        problem = robot_id_error(name)
        if problem:
            raise ConfigError(f"a robot token's name is the robot_id it may push: {problem}")
    now = now or datetime.now(UTC)
    expires_at = None
    if lifetime is not None:  # whole seconds, never sooner than asked
        expires_at = now + lifetime
        if expires_at.microsecond:
            expires_at = expires_at.replace(microsecond=0) + timedelta(seconds=1)
    token = new_token()
    entry = TokenEntry(name=name, role=role.value, sha256=digest(token),
                       created_at=now.replace(microsecond=0), expires_at=expires_at)
    with locked(path):
        entries = load_file(path) if path.exists() else []
        if any(existing.name == name for existing in entries):
            raise ConfigError(f"a token named {name!r} exists in {path}; choose another name "
                              f"or revoke it first (faultledger token revoke {name})")
        entries.append(entry)
        _save(path, entries)
    return token, entry


def revoke(path: Path, name: str) -> TokenEntry:
    """Remove ``name``'s entry from the token file; ``UnknownTokenError`` when it has none."""
    check_name(name)
    with locked(path):
        entries = load_file(path) if path.exists() else []
        kept = [entry for entry in entries if entry.name != name]
        if len(kept) == len(entries):
            known = ", ".join(entry.name for entry in entries) or "none"
            raise UnknownTokenError(f"no token named {name!r} in {path} (its tokens: {known})")
        _save(path, kept)
    return next(entry for entry in entries if entry.name == name)


Signature = tuple[int, ...] | None


def _signature(path: Path | None) -> Signature:
    if path is None:
        return None
    try:
        info = path.stat()
    except FileNotFoundError:
        return None
    except OSError:
        return (-1,)
    return (info.st_dev, info.st_ino, info.st_size, info.st_mtime_ns, info.st_ctime_ns)


class TokenWatcher:
    """Follows the token file of a running server: every ``interval`` seconds (on a thread of
    its own, never on a request) it compares the file's inode, size, mtime and ctime with the last
    look, and on a change reads the tokens again and hands the new ``TokenBook`` to
    ``apply``. A file that does not read or validate keeps the tokens in force and logs one
    line (once per change of the file)."""

    def __init__(self, settings: HttpSettings, apply: Callable[[TokenBook], None],
                 interval: float = WATCH_INTERVAL_SEC) -> None:
        self.settings = settings
        self.apply = apply
        self.interval = interval
        self._seen: Signature = (-2,)
        """Not looked at yet: the first look reads the file again, so a change between the
        server's first read and the watcher's start is not missed."""
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def poll(self) -> bool:
        """Look once; True when new tokens were applied."""
        signature = _signature(self.settings.tokens_file)
        if signature == self._seen:
            return False
        self._seen = signature
        try:
            book = TokenBook(configured(self.settings))
        except FaultLedgerError as error:
            log.warning("token file changed but cannot be used, keeping the tokens in force: "
                        "%s", error)
            return False
        self.apply(book)
        log.info("token file %s changed: %d tokens now", self.settings.tokens_file, len(book))
        return True

    def start(self) -> None:
        if self.settings.tokens_file is None or self._thread is not None:
            return
        self._thread = threading.Thread(target=self._run, name="faultledger-tokens",
                                        daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
            self._thread = None

    def _run(self) -> None:
        while not self._stop.wait(self.interval):
            try:
                self.poll()
            except Exception as error:  # never let the watcher die silently
                log.warning("cannot check the token file: %s: %s", type(error).__name__, error)
