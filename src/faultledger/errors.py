"""Exceptions raised inside faultledger; adapters turn them into messages and exit codes."""

from __future__ import annotations

from enum import StrEnum


class Reason(StrEnum):
    """Machine-readable kind of an answer, beside its message: adapters map it (HTTP status
    codes, exit codes) without parsing text."""

    OK = "ok"
    INVALID = "invalid"
    """The input was refused; nothing was stored."""
    NOT_FOUND = "not_found"
    DUPLICATE = "duplicate"
    """Already recorded (an event_id, a goal outcome): accepted, nothing stored again."""
    CONFLICT = "conflict"
    """The fault's state does not allow it now (acknowledging a CLEARED fault); nothing was
    stored."""
    UNAVAILABLE = "unavailable"
    """The database cannot serve now (locked, full, read-only, damaged, closed)."""
    UNAUTHORIZED = "unauthorized"
    """No valid credentials (HTTP: a missing or unknown bearer token)."""
    FORBIDDEN = "forbidden"
    """Valid credentials whose role does not allow this."""
    TOO_LARGE = "too_large"
    """A request body over the configured limit."""
    INTERNAL = "internal"
    """Something this code did not foresee; the message says what."""


class FaultLedgerError(Exception):
    """Base class: the message is meant for the operator, complete and without a traceback."""

    reason: Reason = Reason.INVALID


class InvalidInputError(FaultLedgerError, ValueError):
    """Input rejected by validation (SPEC §4.5); nothing was stored."""


class ConfigError(FaultLedgerError):
    """A configuration file that cannot be read or does not validate."""


class StoreError(FaultLedgerError):
    """The database cannot do what was asked; the message says why."""

    reason = Reason.UNAVAILABLE


class NotADatabaseError(StoreError):
    pass


class DamagedDatabaseError(StoreError):
    """Stored content this code cannot read back (a damaged or edited file): not a bug."""


class DatabaseReadOnlyError(StoreError):
    pass


class DatabaseLockedError(StoreError):
    pass


class DatabaseFullError(StoreError):
    pass


class WriteConflictError(StoreError):
    """Another process appended the same seq first; the batch is retried after catching up."""


class SchemaTooNewError(StoreError):
    pass


class SchemaOutdatedError(StoreError):
    pass


class IdentityMismatchError(FaultLedgerError):
    """The log records another robot_id than the one this process was told it is; nothing
    was written."""


class LedgerClosedError(FaultLedgerError):
    reason = Reason.UNAVAILABLE


class InternalError(StoreError):
    """An unexpected failure while writing, turned into an answer (the writer's last resort)."""

    reason = Reason.INTERNAL


def clipped(error: BaseException, limit: int = 300) -> str:
    """An unexpected error as one bounded log/answer line: type, message, no traceback."""
    text = repr(f"{type(error).__name__}: {error}")[1:-1]
    return text if len(text) <= limit else f"{text[:limit]}…(+{len(text) - limit} chars)"
