"""The seams the adapters build on (issue "A newcomer's first hour", item 6): a machine-readable
reason on every answer and error, one composition root for ledgers built from configuration,
and a package that exports everything a caller must catch or receives."""

from __future__ import annotations

import importlib.util
import inspect
import os
import stat
import typing
from pathlib import Path
from types import UnionType

import pytest

import faultledger
from faultledger import FaultLedger, Policy, Reason
from faultledger import errors as error_module
from faultledger.errors import ConfigError, InvalidInputError, StoreError
from faultledger.service import bootstrap
from faultledger.service.bootstrap import Role
from faultledger.service.config import Settings, load_settings

CALENDAR = """timezone: Europe/Berlin
shifts:
  - {name: early, start: "05:00", end: "13:00"}
"""


@pytest.fixture
def ledger(tmp_path: Path) -> typing.Iterator[FaultLedger]:
    with FaultLedger.open(f"sqlite:///{tmp_path / 'f.db'}", policy=Policy()) as opened:
        yield opened


# -- reasons -----------------------------------------------------------------------------------
def test_report_answers_carry_their_reason(ledger: FaultLedger) -> None:
    event_id = "5f0c6f5e-4b1e-4e55-a3c9-0d6a1f3c2b10"
    ok = ledger.report("A", "FAILED", 1, "", "/x", event_id=event_id)
    again = ledger.report("A", "FAILED", 1, "", "/x", event_id=event_id)
    bad = ledger.report("A", "FAILED", 9, "", "/x")

    assert [r.reason for r in (ok, again, bad)] == [Reason.OK, Reason.DUPLICATE, Reason.INVALID]


def test_clear_and_lookup_of_an_unknown_fault_say_not_found(ledger: FaultLedger) -> None:
    cleared = ledger.clear("NOPE", actor="op")
    looked = ledger.lookup_fault("NOPE")
    invalid = ledger.lookup_fault("NO PE")

    assert (cleared.reason, looked.reason, invalid.reason) == (
        Reason.NOT_FOUND, Reason.NOT_FOUND, Reason.INVALID)
    assert ledger.lookup_entity("").reason == Reason.INVALID


def test_a_report_the_database_cannot_take_says_unavailable(tmp_path: Path) -> None:
    path = tmp_path / "ro.db"
    with FaultLedger.open(f"sqlite:///{path}", policy=Policy()) as first:
        first.report("A", "FAILED", 1, "", "/x")
    path.chmod(stat.S_IRUSR)
    if os.access(path, os.W_OK):  # root ignores file modes
        os.system(f"chattr +i {path} 2>/dev/null")
    try:
        with FaultLedger.open(f"sqlite:///{path}", upgrade=False) as ledger:
            result = ledger.report("B", "FAILED", 1, "", "/x")
    finally:
        os.system(f"chattr -i {path} 2>/dev/null")
        path.chmod(stat.S_IRUSR | stat.S_IWUSR)
    if result.accepted:
        pytest.skip("this file system lets root write a read-only file")
    assert result.reason == Reason.UNAVAILABLE, result


def test_exceptions_carry_a_reason_by_kind() -> None:
    assert InvalidInputError("x").reason == Reason.INVALID
    assert ConfigError("x").reason == Reason.INVALID
    assert StoreError("x").reason == Reason.UNAVAILABLE
    assert faultledger.DatabaseLockedError("x").reason == Reason.UNAVAILABLE
    assert faultledger.InternalError("x").reason == Reason.INTERNAL


# -- one place builds a ledger from configuration -----------------------------------------------
def test_a_plain_path_is_a_sqlite_file() -> None:
    assert bootstrap.database_url("var/f.db") == "sqlite:///var/f.db"
    assert bootstrap.database_url("/data/faults.db") == "sqlite:////data/faults.db"
    assert bootstrap.database_url("sqlite:///x.db") == "sqlite:///x.db"


def test_a_url_whose_driver_is_missing_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    # A machine without the extra: the dev tools install psycopg, so it is hidden here.
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *rest: None if name == "psycopg" else real(name, *rest))
    with pytest.raises(ConfigError) as refused:
        bootstrap.database_url("postgresql+psycopg://fleet:secret@db/faults")

    message = str(refused.value)
    assert "pip install 'faultledger[postgresql]'" in message and "secret" not in message


@pytest.mark.parametrize("text", ["", "   ", "notascheme://x"])
def test_a_bad_database_url_is_a_config_error(text: str) -> None:
    with pytest.raises(ConfigError):
        bootstrap.database_url(text)


def test_precedence_of_the_database_flag_parameter_and_config() -> None:
    settings = Settings.model_validate({"database": {"url": "sqlite:///config.db"}})

    flag = bootstrap.resolve(settings, Role.READER, db="flag.db", database_path="param.db")
    param = bootstrap.resolve(settings, Role.SERVER, database_path="param.db")
    config = bootstrap.resolve(settings, Role.READER)

    assert (flag.url, param.url, config.url) == (
        "sqlite:///flag.db", "sqlite:///param.db", "sqlite:///config.db")


def test_who_records_a_policy() -> None:
    settings = Settings.model_validate({"policy": {"confirmation_threshold": -3}})
    declared = Policy(confirmation_threshold=-5)

    reader = bootstrap.resolve(settings, Role.READER)
    writer_without_config = bootstrap.resolve(settings, Role.WRITER, config_given=False)
    writer = bootstrap.resolve(settings, Role.WRITER)
    server = bootstrap.resolve(settings, Role.SERVER)
    server_with_parameters = bootstrap.resolve(settings, Role.SERVER, policy=declared)

    assert (reader.policy, writer_without_config.policy) == (None, None)
    assert writer.policy == server.policy == settings.policy
    assert server_with_parameters.policy == declared


def test_the_shift_calendar_flag_wins_over_the_config(tmp_path: Path) -> None:
    shifts = tmp_path / "shifts.yaml"
    shifts.write_text(CALENDAR)
    config = tmp_path / "faultledger.yaml"
    config.write_text("shifts: null\n")
    settings = load_settings(config)

    chosen = bootstrap.resolve(settings, Role.READER, shifts=shifts)
    default = bootstrap.resolve(settings, Role.READER)

    assert chosen.calendar.timezone == "Europe/Berlin"
    assert default.calendar.timezone == "UTC"


def test_a_reader_never_creates_a_database(tmp_path: Path) -> None:
    config = bootstrap.resolve(Settings(), Role.READER, db=str(tmp_path / "missing.db"))

    with pytest.raises(StoreError, match="does not exist"):
        bootstrap.open_ledger(config)
    assert not (tmp_path / "missing.db").exists()


def test_a_server_records_its_policy_and_a_reader_sees_it(tmp_path: Path) -> None:
    db = str(tmp_path / "served.db")
    policy = Policy(confirmation_threshold=-4)
    with bootstrap.open_ledger(bootstrap.resolve(Settings(), Role.SERVER, db=db,
                                                 policy=policy)) as server:
        server.report("A", "FAILED", 1, "", "/x")
    with bootstrap.open_ledger(bootstrap.resolve(Settings(), Role.READER, db=db)) as reader:
        assert reader.policy == policy
        assert reader.last_seq == 3  # the log's identity, the policy, the report


# -- the package exports what callers need -----------------------------------------------------
def _classes(annotation: object) -> set[type]:
    """Classes named in a type annotation (through unions, lists, tuples)."""
    if isinstance(annotation, type) and annotation.__module__.startswith("faultledger"):
        return {annotation}
    found: set[type] = set()
    if isinstance(annotation, UnionType) or typing.get_origin(annotation) is not None:
        for argument in typing.get_args(annotation):
            found |= _classes(argument)
    return found


def test_every_type_a_public_method_returns_is_exported() -> None:
    returned: set[type] = set()
    for name, method in inspect.getmembers(FaultLedger, inspect.isfunction):
        if not name.startswith("_"):
            returned |= _classes(typing.get_type_hints(method).get("return"))

    assert returned, "no annotated return types found"
    missing = sorted(c.__name__ for c in returned
                     if getattr(faultledger, c.__name__, None) is not c)
    assert missing == []


def test_every_exception_is_exported() -> None:
    exceptions = [value for value in vars(error_module).values()
                  if isinstance(value, type) and issubclass(value, faultledger.FaultLedgerError)]

    assert len(exceptions) >= 10
    assert sorted(e.__name__ for e in exceptions
                  if getattr(faultledger, e.__name__, None) is not e) == []
