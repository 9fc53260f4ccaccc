"""Audit history (issue 5): filters of ``FaultLedger.history`` and ``faultledger history``, and
the CSV / JSON Lines exports, whose hashes must be recomputable from the export alone.

Every answer is compared with a plain Python filter over the whole log, on a real SQLite file.
"""

from __future__ import annotations

import csv
import io
import json
import os
import subprocess
import sys
import tracemalloc
from collections.abc import Callable, Iterator
from datetime import UTC, datetime, timedelta
from fnmatch import fnmatchcase
from pathlib import Path
from typing import Any

import pytest

from faultledger import FaultLedger, Policy
from faultledger.domain.clock import to_ns
from faultledger.domain.events import KINDS, LogRecord
from faultledger.domain.integrity import GENESIS_HASH, canonical_json, record_hash
from faultledger.errors import InvalidInputError
from faultledger.service.audit import export_history
from faultledger.service.requests import ReportRequest
from faultledger.store import event_log, log_index

T0 = datetime(2026, 11, 21, 22, 0, tzinfo=UTC)
CLI = [sys.executable, "-m", "faultledger.cli.main"]

# (code, FAILED/PASSED, source); one report a second from T0.
STEPS = [
    ("HW_LEFT_EMERGENCY_STOP", "FAILED", "/robot/left"),
    ("HW_RIGHT_EMERGENCY_STOP", "FAILED", "/robot/right"),
    ("HW_LEFT_PROTECTIVE_STOP", "FAILED", "/robot/left"),
    ("ACTION_NAVIGATE_ABORTED", "FAILED", "/nav"),
    ("hw_left_emergency_stop", "FAILED", "/robot/left"),  # other case: a glob must not match
    ("HW_LEFT_EMERGENCY_STOP", "PASSED", "/robot/left"),
    ("HW_LEFT_EMERGENCY_STOP", "FAILED", "/robot/left"),
    ("ACTION_DOCK_ABORTED", "FAILED", "/dock"),
    ("HW_RIGHT_EMERGENCY_STOP", "FAILED", "/robot/right"),
    ("HW_LEFT", "FAILED", "/robot/left"),  # a prefix of other codes: exact must stay exact
    ("ACTION_NAVIGATE_ABORTED", "PASSED", "/nav"),
]


def build_log(url: str) -> None:
    """Reports over several codes and sources, a timer confirmation, a clear and a policy."""
    policy = Policy(confirmation_threshold=-2, auto_confirm_after_sec=5.0)
    with FaultLedger.open(url, policy=policy, background=False) as ledger:
        for i, (code, kind, source) in enumerate(STEPS):
            result = ledger.report(code, kind, severity=2, description=f"step {i}",
                                   source_id=source, at=T0 + timedelta(seconds=i))
            assert result.accepted, result.message
        assert ledger.run_timers(now=T0 + timedelta(seconds=60)) > 0
        cleared = ledger.clear("HW_RIGHT_EMERGENCY_STOP", actor="cli:alice", reason="reset",
                               at=T0 + timedelta(seconds=70))
        assert cleared.success, cleared.message


@pytest.fixture(scope="module")
def log_url(tmp_path_factory: pytest.TempPathFactory) -> str:
    url = f"sqlite:///{tmp_path_factory.mktemp('audit') / 'faults.db'}"
    build_log(url)
    return url


@pytest.fixture
def ledger(log_url: str) -> Iterator[FaultLedger]:
    with FaultLedger.open(log_url) as opened:
        yield opened


def run_cli(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    done = subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=60,
                          env=None if env is None else {**os.environ, **env})
    assert "Traceback" not in done.stderr, done.stderr
    return done


def ns(seconds: float) -> int:
    return to_ns(T0) + int(seconds * 1_000_000_000)


# -- the service API -----------------------------------------------------------------------------
Check = Callable[[LogRecord], bool]
FILTERS: list[tuple[str, dict[str, Any], Check]] = [
    ("exact-code", {"codes": ["HW_LEFT_EMERGENCY_STOP"]},
     lambda r: r.fault_code == "HW_LEFT_EMERGENCY_STOP"),
    ("exact-code-is-not-a-prefix", {"codes": ["HW_LEFT"]}, lambda r: r.fault_code == "HW_LEFT"),
    ("glob", {"codes": ["HW_*_EMERGENCY_STOP"]},
     lambda r: r.fault_code in ("HW_LEFT_EMERGENCY_STOP", "HW_RIGHT_EMERGENCY_STOP")),
    ("glob-is-case-sensitive", {"codes": ["hw_*"]},
     lambda r: r.fault_code == "hw_left_emergency_stop"),
    ("globs-and-exact", {"codes": ["HW_*_EMERGENCY_STOP", "ACTION_*_ABORTED", "HW_LEFT"]},
     lambda r: r.fault_code is not None and (fnmatchcase(r.fault_code, "HW_*_EMERGENCY_STOP")
                                             or r.fault_code.startswith("ACTION_")
                                             or r.fault_code == "HW_LEFT")),
    ("glob-question-and-class", {"codes": ["HW_[LR]?????_*"]},
     lambda r: r.fault_code is not None and fnmatchcase(r.fault_code, "HW_[LR]?????_*")),
    ("glob-without-literal-prefix", {"codes": ["*_ABORTED"]},
     lambda r: r.fault_code is not None and r.fault_code.endswith("_ABORTED")),
    ("glob-matching-nothing", {"codes": ["NOPE_*"]}, lambda r: False),
    ("code-and-codes", {"code": "HW_LEFT", "codes": ["HW_*"]},
     lambda r: r.fault_code == "HW_LEFT"),
    ("source", {"source": "/robot/left"}, lambda r: r.source_id == "/robot/left"),
    ("clear-actor-is-the-source", {"source": "cli:alice"}, lambda r: r.kind == "fault_cleared"),
    ("one-kind", {"kinds": ["fault_confirmed_by_timer"]},
     lambda r: r.kind == "fault_confirmed_by_timer"),
    ("kinds", {"kinds": ["policy_changed", "fault_cleared"]},
     lambda r: r.kind in ("policy_changed", "fault_cleared")),
    ("since-until-datetimes", {"since": T0 + timedelta(seconds=2),
                               "until": T0 + timedelta(seconds=5)},
     lambda r: ns(2) <= r.occurred_at_ns < ns(5)),
    ("since-until-ns", {"since": ns(3), "until": ns(3) + 1}, lambda r: r.occurred_at_ns == ns(3)),
    ("seq-range", {"from_seq": 4, "to_seq": 9}, lambda r: 4 <= r.seq <= 9),
    ("from-seq-only", {"from_seq": 12}, lambda r: r.seq >= 12),
    ("to-seq-only", {"to_seq": 1}, lambda r: r.seq <= 1),
    ("everything-at-once", {"codes": ["HW_*"], "source": "/robot/left", "kinds": ["fault_reported"],
                            "since": T0 + timedelta(seconds=1), "until": T0 + timedelta(seconds=9),
                            "from_seq": 3, "to_seq": 10},
     lambda r: (r.fault_code or "").startswith("HW_") and r.source_id == "/robot/left"
     and r.kind == "fault_reported" and ns(1) <= r.occurred_at_ns < ns(9) and 3 <= r.seq <= 10),
]


@pytest.mark.parametrize(("name", "filters", "check"), FILTERS, ids=[f[0] for f in FILTERS])
def test_history_filters_equal_a_filter_over_the_whole_log(
        ledger: FaultLedger, name: str, filters: dict[str, Any], check: Check) -> None:
    everything = ledger.history()
    expected = [r for r in everything if check(r)]
    found = ledger.history(**filters)
    assert found == expected
    assert [r.seq for r in export_history(ledger, **filters)] == [r.seq for r in expected]


def test_the_log_holds_the_kinds_the_filters_are_checked_on(ledger: FaultLedger) -> None:
    kinds = {r.kind for r in ledger.history()}
    assert kinds >= {"policy_changed", "fault_reported", "fault_confirmed_by_timer",
                     "fault_cleared"}
    globbed = {r.fault_code for r in ledger.history(codes=["HW_*_EMERGENCY_STOP"])}
    assert globbed == {"HW_LEFT_EMERGENCY_STOP", "HW_RIGHT_EMERGENCY_STOP"}


def test_existing_callers_keep_working(ledger: FaultLedger) -> None:
    """The ROS node's call: exact code, ns bounds, source, kinds, limit (positional too)."""
    found = ledger.history(code="HW_LEFT_EMERGENCY_STOP", since=ns(0), until=ns(7),
                           source="/robot/left", kinds=["fault_reported"], limit=2)
    assert [(r.fault_code, r.occurred_at_ns) for r in found] == [
        ("HW_LEFT_EMERGENCY_STOP", ns(0)), ("HW_LEFT_EMERGENCY_STOP", ns(5))]
    assert ledger.history("HW_LEFT", None, None, "/robot/left", (), 1)[0].fault_code == "HW_LEFT"
    assert ledger.history(code="HW_*") == []  # ``code`` is one exact code, never a glob
    assert ledger.history(limit=3) == ledger.history()[:3]


def test_codes_given_as_one_string_is_one_pattern(ledger: FaultLedger) -> None:
    assert ledger.history(codes="HW_LEFT") == ledger.history(codes=["HW_LEFT"])


def test_unknown_kind_is_an_error_listing_the_valid_kinds(ledger: FaultLedger) -> None:
    with pytest.raises(InvalidInputError) as raised:
        ledger.history(kinds=["fault_reported", "fault_exploded"])
    message = str(raised.value)
    assert "'fault_exploded'" in message
    assert all(kind in message for kind in KINDS)
    with pytest.raises(InvalidInputError):
        export_history(ledger, kinds=["FAULT_REPORTED"])  # kinds are case-sensitive


@pytest.mark.parametrize(("bounds", "words"), [
    ({"from_seq": 5, "to_seq": 4}, "from_seq 5 is after to_seq 4"),
    ({"from_seq": 0}, "from_seq must be a seq number of 1 or more"),
    ({"to_seq": -3}, "to_seq must be a seq number of 1 or more"),
    ({"since": datetime(2026, 11, 21, 22, 0)}, "since must be a timezone-aware datetime"),
])
def test_bad_bounds_are_errors(ledger: FaultLedger, bounds: dict[str, Any], words: str) -> None:
    with pytest.raises(InvalidInputError, match=words):
        ledger.history(**bounds)


def test_distinct_codes_and_glob_expansion_use_the_stored_codes(ledger: FaultLedger,
                                                                 log_url: str) -> None:
    from faultledger.store.database import Database

    stored = sorted({r.fault_code for r in ledger.history() if r.fault_code is not None})
    database = Database(log_url, create=False)
    try:
        with database.reading() as conn:
            assert log_index.distinct_codes(conn) == stored
            assert log_index.distinct_codes(conn, "HW_") == [
                c for c in stored if c.startswith("HW_")]
            assert event_log.matching_codes(conn, ["HW_*_STOP", "ACTION_D*", "UNKNOWN"]) == sorted(
                [c for c in stored if fnmatchcase(c, "HW_*_STOP") or c.startswith("ACTION_D")]
                + ["UNKNOWN"])
    finally:
        database.dispose()


def test_export_rows_are_the_stored_rows_with_the_previous_hash(ledger: FaultLedger) -> None:
    records = ledger.history()
    rows = list(export_history(ledger))
    assert [r.seq for r in rows] == [r.seq for r in records]
    previous = GENESIS_HASH
    for row, record in zip(rows, records, strict=True):
        assert (row.event_id, row.kind, row.fault_code, row.source_id, row.hash) == (
            record.event_id, record.kind, record.fault_code, record.source_id, record.hash)
        assert row.payload_json == canonical_json(record.payload)
        assert row.prev_hash == previous
        assert record_hash(row.prev_hash, row.seq, row.event_id, row.kind, row.fault_code,
                           row.source_id, row.payload_json, row.occurred_at_ns,
                           row.recorded_at_ns, row.schema_version) == row.hash
        previous = row.hash


def test_export_is_streamed_not_built_in_memory(tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """Rows come in chunks of READ_CHUNK: the export's peak memory stays far below the list's."""
    url = f"sqlite:///{tmp_path / 'many.db'}"
    with FaultLedger.open(url, background=False) as ledger:
        for batch in range(6):
            results = ledger.report_many([
                ReportRequest(f"HW_{i % 40}_EMERGENCY_STOP", "FAILED", 2, "x" * 200, "/robot",
                              T0 + timedelta(milliseconds=batch * 1000 + i))
                for i in range(500)])
            assert all(r.accepted for r in results)
        monkeypatch.setattr(event_log, "READ_CHUNK", 100)
        tracemalloc.start()
        try:
            count = sum(1 for _ in export_history(ledger, codes=["HW_*"]))
            streamed = tracemalloc.get_traced_memory()[1]
            tracemalloc.reset_peak()
            listed = len(ledger.history(codes=["HW_*"]))
            whole = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    assert count == listed == 3000
    assert streamed * 4 < whole, (streamed, whole)


# -- the CLI -------------------------------------------------------------------------------------
def parse_jsonl(text: str) -> list[dict[str, Any]]:
    return [json.loads(line) for line in text.splitlines()]


def recompute(row: dict[str, Any], payload_json: str) -> str:
    return record_hash(row["prev_hash"], row["seq"], row["event_id"], row["kind"],
                       row["fault_code"], row["source_id"], payload_json,
                       row["occurred_at_ns"], row["recorded_at_ns"], row["schema_version"])


def test_jsonl_export_round_trips_and_recomputes_the_whole_chain(ledger: FaultLedger,
                                                                 log_url: str) -> None:
    done = run_cli("history", "--db", log_url, "--format", "jsonl")
    assert done.returncode == 0, done.stderr
    rows = parse_jsonl(done.stdout)
    records = ledger.history()
    identity = ledger.identity
    assert len(rows) == len(records) and identity is not None
    previous = GENESIS_HASH
    for row, record in zip(rows, records, strict=True):
        assert row == {
            "seq": record.seq, "event_id": record.event_id, "kind": record.kind,
            "fault_code": record.fault_code, "source_id": record.source_id,
            "occurred_at": row["occurred_at"], "occurred_at_ns": record.occurred_at_ns,
            "recorded_at": row["recorded_at"], "recorded_at_ns": record.recorded_at_ns,
            "schema_version": record.schema_version, "payload": record.payload,
            "prev_hash": previous, "hash": record.hash,
            "robot_id": identity.robot_id, "ledger_id": identity.ledger_id,
        }
        assert datetime.fromisoformat(row["occurred_at"]) == record.occurred_at
        assert row["occurred_at"].endswith(f".{record.occurred_at_ns % 10**9:09d}+00:00")
        # Only the export: the chain from the genesis hash reproduces every stored hash.
        assert recompute(row, canonical_json(row["payload"])) == row["hash"]
        previous = row["hash"]


def test_json_flag_is_json_lines_too(log_url: str) -> None:
    by_flag = run_cli("history", "--db", log_url, "--json", "--kind", "fault_cleared")
    by_format = run_cli("history", "--db", log_url, "--format", "jsonl", "--kind",
                        "fault_cleared")
    assert by_flag.returncode == by_format.returncode == 0
    assert by_flag.stdout == by_format.stdout
    assert [row["kind"] for row in parse_jsonl(by_flag.stdout)] == ["fault_cleared"]


def test_csv_export_round_trips_and_each_hash_recomputes(ledger: FaultLedger,
                                                         log_url: str) -> None:
    done = run_cli("history", "--db", log_url, "--csv", "--code", "HW_*_EMERGENCY_STOP",
                   "--code", "ACTION_*")
    assert done.returncode == 0, done.stderr
    rows = list(csv.DictReader(io.StringIO(done.stdout)))
    records = ledger.history(codes=["HW_*_EMERGENCY_STOP", "ACTION_*"])
    assert records and len(rows) == len(records)
    by_seq = {r.seq: r.hash for r in ledger.history()}
    for row, record in zip(rows, records, strict=True):
        assert row["kind"] in ("fault_reported", "fault_cleared", "fault_confirmed_by_timer")
        assert (int(row["seq"]), row["event_id"], row["kind"], row["fault_code"],
                row["payload"], int(row["occurred_at_ns"]), row["hash"]) == (
            record.seq, record.event_id, record.kind, record.fault_code,
            canonical_json(record.payload), record.occurred_at_ns, record.hash)
        assert row["prev_hash"] == by_seq.get(record.seq - 1, GENESIS_HASH)
        # NULL is an empty cell; only reports and clears have a source (docs/operations.md).
        source = row["source_id"] if row["kind"] in ("fault_reported", "fault_cleared") else None
        assert source == record.source_id
        typed = {**row, "seq": int(row["seq"]), "source_id": source,
                 "occurred_at_ns": int(row["occurred_at_ns"]),
                 "recorded_at_ns": int(row["recorded_at_ns"]),
                 "schema_version": int(row["schema_version"])}
        assert recompute(typed, row["payload"]) == row["hash"]


def test_cli_filters_match_the_api(ledger: FaultLedger, log_url: str) -> None:
    cases: list[tuple[list[str], dict[str, Any]]] = [
        (["--code", "HW_*_EMERGENCY_STOP"], {"codes": ["HW_*_EMERGENCY_STOP"]}),
        (["--code", "HW_LEFT"], {"codes": ["HW_LEFT"]}),
        (["--source", "/robot/right", "--kind", "fault_reported", "--kind", "fault_cleared"],
         {"source": "/robot/right", "kinds": ["fault_reported", "fault_cleared"]}),
        (["--since", "2026-11-21T22:00:02Z", "--until", "2026-11-21T22:00:06+00:00"],
         {"since": T0 + timedelta(seconds=2), "until": T0 + timedelta(seconds=6)}),
        (["--since", "2026-11-21T23:00:03+01:00"], {"since": T0 + timedelta(seconds=3)}),
        (["--from-seq", "3", "--to-seq", "7"], {"from_seq": 3, "to_seq": 7}),
        (["--code", "ACTION_*", "--limit", "2"], {"codes": ["ACTION_*"], "limit": 2}),
    ]
    for args, filters in cases:
        done = run_cli("history", "--db", log_url, "--format", "jsonl", *args)
        assert done.returncode == 0, (args, done.stderr)
        expected = [r.seq for r in ledger.history(**filters)]
        assert [row["seq"] for row in parse_jsonl(done.stdout)] == expected, args
        assert expected, args


def test_a_date_alone_is_midnight(ledger: FaultLedger, log_url: str) -> None:
    done = run_cli("history", "--db", log_url, "--json", "--until", "2026-11-22",
                   env={"TZ": "UTC"})
    assert done.returncode == 0, done.stderr
    expected = ledger.history(until=datetime(2026, 11, 22, tzinfo=UTC))
    assert [row["seq"] for row in parse_jsonl(done.stdout)] == [r.seq for r in expected]


def test_a_time_without_offset_is_in_the_calendars_zone(ledger: FaultLedger, log_url: str,
                                                        tmp_path: Path) -> None:
    """docs/cli.md, Times: a naive time is in the shift calendar's zone (UTC by default),
    whatever the machine's zone, as in `stats`."""
    done = run_cli("history", "--db", log_url, "--json", "--since", "2026-11-21T22:00:04",
                   env={"TZ": "Asia/Tokyo"})  # the machine's zone does not matter
    assert done.returncode == 0, done.stderr
    expected = ledger.history(since=T0 + timedelta(seconds=4))
    assert [row["seq"] for row in parse_jsonl(done.stdout)] == [r.seq for r in expected]
    shifts = tmp_path / "shifts.yaml"
    shifts.write_text("timezone: Asia/Tokyo\nshifts:\n  - {name: day, start: '08:00', "
                      "end: '20:00'}\n  - {name: night, start: '20:00', end: '08:00'}\n")
    done = run_cli("history", "--db", log_url, "--json", "--shifts", str(shifts),
                   "--since", "2026-11-22T07:00:04", env={"TZ": "UTC"})  # UTC+9, no DST
    assert done.returncode == 0, done.stderr
    assert [row["seq"] for row in parse_jsonl(done.stdout)] == [r.seq for r in expected]


def test_shift_ids_bound_history(ledger: FaultLedger, log_url: str) -> None:
    """A shift id is its start as --since and its end as --until (the default calendar:
    night 22:00-06:00 UTC)."""
    done = run_cli("history", "--db", log_url, "--json", "--since", "2026-11-21/night",
                   "--until", "2026-11-21/night")
    assert done.returncode == 0, done.stderr
    expected = ledger.history(since=T0, until=T0 + timedelta(hours=8))
    assert [row["seq"] for row in parse_jsonl(done.stdout)] == [r.seq for r in expected]
    assert expected
    done = run_cli("history", "--db", log_url, "--json", "--until", "2026-11-21/night")
    assert done.returncode == 0, done.stderr
    assert len(parse_jsonl(done.stdout)) == len(ledger.history(until=T0 + timedelta(hours=8)))
    done = run_cli("history", "--db", log_url, "--since", "2026-11-21/lunch")
    assert done.returncode == 2
    assert done.stderr.startswith("error: --since: no shift 'lunch'"), done.stderr


def test_table_is_the_default(log_url: str) -> None:
    done = run_cli("history", "--db", log_url, "--code", "HW_*_EMERGENCY_STOP")
    assert done.returncode == 0, done.stderr
    assert "HW_RIGHT_EMERGENCY_STOP" in done.stdout
    assert "HW_LEFT_PROTECTIVE_STOP" not in done.stdout
    assert "hw_left_emergency_stop" not in done.stdout


def test_output_file_gets_the_whole_export(ledger: FaultLedger, log_url: str,
                                           tmp_path: Path) -> None:
    target = tmp_path / "audit.jsonl"
    done = run_cli("history", "--db", log_url, "--format", "jsonl", "--output", str(target))
    assert done.returncode == 0, done.stderr
    assert done.stdout == ""
    assert f"wrote {len(ledger.history())} records" in done.stderr
    assert [row["seq"] for row in parse_jsonl(target.read_text(encoding="utf-8"))] == [
        r.seq for r in ledger.history()]
    assert list(tmp_path.iterdir()) == [target]  # no partial file left behind


@pytest.mark.parametrize(("args", "words"), [
    (["--kind", "fault_exploded"], "unknown record kind 'fault_exploded'; valid kinds: "
     "fault_reported, fault_cleared, fault_confirmed_by_timer, policy_changed, "
     "reclassified_on_startup"),
    (["--from-seq", "9", "--to-seq", "3"], "--from-seq 9 is after --to-seq 3"),
    (["--since", "last tuesday"], "--since must be an ISO 8601 date or time"),
    (["--until", "2026-13-01"], "--until must be an ISO 8601 date or time"),
    (["--json", "--csv"], "choose one output format"),
    (["--format", "csv", "--json"], "choose one output format"),
    (["--output", "x.csv"], "--output writes an export"),
])
def test_bad_input_is_one_clear_line_and_exit_2(log_url: str, args: list[str],
                                                words: str) -> None:
    done = run_cli("history", "--db", log_url, *args)
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert words in done.stderr
    assert done.stdout == ""


def test_usage_errors_exit_2_without_traceback(log_url: str) -> None:
    for args in (["--format", "xml"], ["--from-seq", "0"], ["--limit", "zero"]):
        done = run_cli("history", "--db", log_url, *args)
        assert done.returncode == 2, (args, done.stderr)


def test_missing_database_is_reported(tmp_path: Path) -> None:
    done = run_cli("history", "--db", f"sqlite:///{tmp_path / 'none.db'}", "--json")
    assert done.returncode == 2
    assert "does not exist" in done.stderr
    assert not (tmp_path / "none.db").exists()


def documented_check_script() -> str:
    """The export checker printed in docs/operations.md ("Proving a historical state")."""
    doc = (Path(__file__).parent.parent / "docs" / "operations.md").read_text(encoding="utf-8")
    start = doc.index("# check_export.py")
    return doc[start:doc.index("```", start)]


def test_documented_check_script_accepts_an_export_and_rejects_a_gap(log_url: str,
                                                                     tmp_path: Path) -> None:
    script = tmp_path / "check_export.py"
    script.write_text(documented_check_script(), encoding="utf-8")
    export = tmp_path / "prefix.jsonl"
    done = run_cli("history", "--db", log_url, "--format", "jsonl", "--to-seq", "8",
                   "--output", str(export))
    assert done.returncode == 0, done.stderr
    lines = export.read_text(encoding="utf-8").splitlines()
    last_hash = json.loads(lines[-1])["hash"]

    def check(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, str(script), *args], capture_output=True,
                              text=True, timeout=60)

    ok = check(str(export))
    assert ok.returncode == 0, ok.stderr
    assert ok.stdout.strip() == f"chain intact; last hash {last_hash}"
    rest = tmp_path / "rest.jsonl"
    assert run_cli("history", "--db", log_url, "--json", "--from-seq", "9", "--output",
                   str(rest)).returncode == 0
    assert check(str(rest), last_hash).returncode == 0  # continues from the anchored hash
    export.write_text("\n".join(lines[:3] + lines[4:]) + "\n", encoding="utf-8")
    gap = check(str(export))
    assert gap.returncode == 1
    assert "seq 5: a record before it is missing" in gap.stderr
    edited = json.loads(lines[5])
    edited["payload"]["description"] = "nothing happened"
    export.write_text("\n".join([*lines[:5], json.dumps(edited)]) + "\n", encoding="utf-8")
    assert f"seq {edited['seq']} does not match its hash" in check(str(export)).stderr
