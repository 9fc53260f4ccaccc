"""Exceptions raised inside faultledger; adapters turn them into messages and exit codes."""

from __future__ import annotations


class FaultLedgerError(Exception):
    """Base class: the message is meant for the operator, complete and without a traceback."""


class InvalidInputError(FaultLedgerError, ValueError):
    """Input rejected by validation (SPEC §4.5); nothing was stored."""


class ConfigError(FaultLedgerError):
    """A configuration file that cannot be read or does not validate."""


class StoreError(FaultLedgerError):
    """The database cannot do what was asked; the message says why."""


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


class LedgerClosedError(FaultLedgerError):
    pass
