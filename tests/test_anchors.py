"""Signed anchors (issue "Hardening", item 5): what the hash chain alone cannot prove.

Each scenario builds a real log (test_tamper's), anchors it with a real Ed25519 key, tampers
with the SQLite file through the ``sqlite3`` module exactly as someone with write access could,
and checks what ``faultledger verify`` says with and without the anchor. The key scenarios run
the CLI in a subprocess; the scheduler `serve` uses is driven directly (no ROS needed).
"""

from __future__ import annotations

import base64
import json
import logging
import os
import sqlite3
import stat
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

from faultledger import FaultLedger, Policy
from faultledger.domain.integrity import canonical_json, record_hash
from faultledger.errors import ConfigError
from faultledger.service import anchors
from faultledger.service.config import load_settings
from tests.test_tamper import CLI, LENGTH, build_log, tamper

T0 = datetime(2026, 11, 21, 22, 0, tzinfo=UTC)


# -- helpers -------------------------------------------------------------------------------------
def run(*args: str, cwd: Path | None = None, umask: int | None = None
        ) -> subprocess.CompletedProcess[str]:
    """The real CLI in a subprocess; it never prints a traceback."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("FAULTLEDGER_DB", "FAULTLEDGER_CONFIG")}
    done = subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=120, cwd=cwd,
                          env=env, umask=-1 if umask is None else umask)
    assert "Traceback" not in done.stderr, done.stderr
    return done


def url(db: Path) -> str:
    return f"sqlite:///{db}"


def write_keys(directory: Path, name: str = "anchor") -> tuple[Path, Path]:
    """A key pair as PEM files (through the same code `anchor keygen` uses)."""
    _, private_pem, public_pem = anchors.new_key_pair()
    private, public = directory / f"{name}.pem", directory / f"{name}.pub"
    private.write_bytes(private_pem)
    public.write_bytes(public_pem)
    return private, public


def export(db: Path, key: Path, output: Path) -> None:
    done = run("anchor", "export", "--key", str(key), "--output", str(output), "--db", url(db))
    assert done.returncode == 0, done.stderr
    assert output.is_file()


def verify_cli(db: Path, public: Path, *anchor_files: Path, json_out: bool = False
               ) -> subprocess.CompletedProcess[str]:
    args = ["verify", "--db", url(db), "--public-key", str(public)]
    for path in anchor_files:
        args += ["--anchor", str(path)]
    return run(*args, *(["--json"] if json_out else []))


def stored(db: Path, sql: str, *params: object) -> list[tuple[object, ...]]:
    with sqlite3.connect(db) as conn:
        rows = conn.execute(sql, params).fetchall()
    conn.close()
    return rows


def head(db: Path) -> tuple[int, str]:
    seq, digest = stored(db, "SELECT seq, hash FROM events ORDER BY seq DESC LIMIT 1")[0]
    return int(str(seq)), str(digest)


def rehash_from(db: Path, first: int) -> None:
    """Recompute every hash from record ``first`` on and move the checkpoint to the new head:
    a forgery the chain alone cannot tell from the real log."""
    with sqlite3.connect(db) as conn:
        prev = conn.execute("SELECT hash FROM events WHERE seq = ?", (first - 1,)).fetchone()
        prev_hash = "0" * 64 if prev is None else str(prev[0])
        rows = conn.execute(
            "SELECT seq, event_id, kind, fault_code, source_id, payload, occurred_at_ns, "
            "recorded_at_ns, schema_version FROM events WHERE seq >= ? ORDER BY seq",
            (first,)).fetchall()
        for seq, event_id, kind, code, source, payload, occurred, recorded, version in rows:
            prev_hash = record_hash(prev_hash, seq, event_id, kind, code, source, payload,
                                    occurred, recorded, version)
            conn.execute("UPDATE events SET hash = ? WHERE seq = ?", (prev_hash, seq))
        conn.execute("UPDATE checkpoints SET hash = ? WHERE seq = (SELECT max(seq) FROM events)",
                     (prev_hash,))
    conn.close()


def forge_description(db: Path, seq: int, text: str = "nothing happened") -> None:
    """Change the description of FAILED record ``seq`` and re-hash everything after it."""
    (payload,) = stored(db, "SELECT payload FROM events WHERE seq = ?", seq)[0]
    data = json.loads(str(payload))
    assert data["event_type"] in ("FAILED", 0), data
    data["description"] = text
    tamper(db, ("UPDATE events SET payload = ? WHERE seq = ?", (canonical_json(data), seq)))
    rehash_from(db, seq)


def append_reports(db: Path, count: int) -> int:
    """``count`` more reports through the API; the new head seq."""
    with FaultLedger.open(url(db), background=False) as ledger:
        for i in range(count):
            result = ledger.report("WHEEL_SLIP", "FAILED", severity=1, description=f"slip {i}",
                                   source_id="/robot/wheel", at=T0 + timedelta(minutes=i + 1))
            assert result.accepted, result.message
        return ledger.last_seq


@pytest.fixture
def db(tmp_path: Path) -> Path:
    path = tmp_path / "faults.db"
    assert build_log(path) == LENGTH
    return path


@pytest.fixture
def keys(tmp_path: Path) -> tuple[Path, Path]:
    return write_keys(tmp_path)


# -- keygen, export, an untouched log --------------------------------------------------------------
def test_keygen_export_and_verify_an_untouched_log(tmp_path: Path, db: Path) -> None:
    private, public = tmp_path / "keys" / "robot.pem", tmp_path / "keys" / "robot.pub"
    private.parent.mkdir()
    made = run("anchor", "keygen", "--private-key", str(private), "--public-key", str(public),
               umask=0)
    assert made.returncode == 0, made.stderr
    assert stat.S_IMODE(private.stat().st_mode) == 0o600  # whatever the umask
    trusted = anchors.load_public_key(public)
    assert anchors.key_id(trusted) in made.stdout
    assert anchors.load_private_key(private).public_key() == trusted

    printed = run("anchor", "--key", str(private), "--db", url(db))  # `export` is the default
    assert printed.returncode == 0, printed.stderr
    document = json.loads(printed.stdout)
    seq, digest = head(db)
    (recorded,) = stored(db, "SELECT recorded_at_ns FROM events WHERE seq = ?", seq)[0]
    assert {k: document[k] for k in ("format", "seq", "hash", "recorded_at_ns", "key_id")} == {
        "format": "faultledger-anchor/1", "seq": LENGTH, "hash": digest, "recorded_at_ns": recorded,
        "key_id": anchors.key_id(trusted)}
    assert document["recorded_at"].startswith(
        datetime.fromtimestamp(int(str(recorded)) // 10**9, tz=UTC).strftime("%Y-%m-%dT%H:%M:%S"))
    assert abs(document["anchored_at_ns"] - time.time_ns()) < 120 * 10**9
    signature = base64.b64decode(document.pop("signature"))
    trusted.verify(signature, canonical_json(document).encode())  # raises when it does not match

    anchor_file = tmp_path / f"a{LENGTH}.json"
    written = run("anchor", "export", "--key", str(private), "--output", str(anchor_file),
                  "--db", url(db), umask=0)
    assert written.returncode == 0, written.stderr
    assert stat.S_IMODE(anchor_file.stat().st_mode) == 0o640
    checked = verify_cli(db, public, anchor_file)
    assert checked.returncode == 0, checked.stdout + checked.stderr
    assert checked.stdout.startswith(f"OK: {LENGTH} records")
    assert f"anchor {anchor_file}: seq {LENGTH} hash {digest}" in checked.stdout
    as_json = json.loads(verify_cli(db, public, anchor_file, json_out=True).stdout)
    assert as_json["ok"] and as_json["anchors"][0]["seq"] == LENGTH


def test_an_empty_log_is_not_anchored(tmp_path: Path, keys: tuple[Path, Path]) -> None:
    empty = tmp_path / "empty.db"
    assert run("db", "upgrade", "--db", url(empty)).returncode == 0
    done = run("anchor", "--key", str(keys[0]), "--db", url(empty))
    assert done.returncode == 1
    assert "empty" in done.stderr and done.stdout == ""


# -- what the chain alone misses -------------------------------------------------------------------
def test_tail_deletion_with_checkpoint_update_and_rebuild(tmp_path: Path, db: Path,
                                                          keys: tuple[Path, Path]) -> None:
    private, public = keys
    anchor_file = tmp_path / f"a{LENGTH}.json"
    export(db, private, anchor_file)
    (hash10,) = stored(db, "SELECT hash FROM events WHERE seq = 10")[0]
    tamper(db, ("DELETE FROM events WHERE seq > ?", (10,)),
           ("UPDATE checkpoints SET seq = ?, hash = ?", (10, hash10)))
    rebuilt = run("rebuild", "--db", url(db))
    assert rebuilt.returncode == 0, rebuilt.stderr

    plain = run("verify", "--db", url(db))
    assert plain.returncode == 0, plain.stderr  # the known limit (docs/operations.md)
    assert plain.stdout.startswith("OK: 10 records")

    anchored = verify_cli(db, public, anchor_file)
    assert anchored.returncode == 1
    assert "first bad seq: 11" in anchored.stdout
    assert f"records 11..{LENGTH} were removed" in anchored.stderr
    assert str(anchor_file) in anchored.stderr


def test_rehashed_forgery_is_found_only_with_an_anchor(tmp_path: Path, db: Path,
                                                       keys: tuple[Path, Path]) -> None:
    private, public = keys
    anchor_file = tmp_path / f"a{LENGTH}.json"
    export(db, private, anchor_file)
    forge_description(db, 3)
    assert run("rebuild", "--db", url(db)).returncode == 0

    plain = run("verify", "--db", url(db))
    assert plain.returncode == 0, plain.stderr  # consistent: the chain alone cannot tell

    anchored = verify_cli(db, public, anchor_file)
    assert anchored.returncode == 1
    assert "first bad seq: 1" in anchored.stdout.splitlines()
    assert f"records in (0, {LENGTH}] were changed or replaced" in anchored.stderr


def test_two_anchors_a_forgery_between_them(tmp_path: Path, db: Path,
                                            keys: tuple[Path, Path]) -> None:
    private, public = keys
    first, second = tmp_path / f"a{LENGTH}.json", tmp_path / f"a{LENGTH + 7}.json"
    export(db, private, first)
    assert append_reports(db, 7) == LENGTH + 7
    export(db, private, second)
    forge_description(db, LENGTH + 2)

    anchored = verify_cli(db, public, second, first)  # checked in seq order, not as given
    assert anchored.returncode == 1
    assert f"first bad seq: {LENGTH + 1}" in anchored.stdout.splitlines()
    assert f"records in ({LENGTH}, {LENGTH + 7}] were changed or replaced" in anchored.stderr
    assert str(second) in anchored.stderr and str(first) not in anchored.stderr


def test_records_appended_after_the_anchor_still_verify(tmp_path: Path, db: Path,
                                                        keys: tuple[Path, Path]) -> None:
    private, public = keys
    anchor_file = tmp_path / f"a{LENGTH}.json"
    export(db, private, anchor_file)
    assert append_reports(db, 3) == LENGTH + 3
    done = verify_cli(db, public, anchor_file)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith(f"OK: {LENGTH + 3} records")
    assert f"seq {LENGTH}" in done.stdout


# -- anchors that cannot be trusted ----------------------------------------------------------------
def test_anchor_signed_by_another_key_fails(tmp_path: Path, db: Path,
                                            keys: tuple[Path, Path]) -> None:
    other_private, _ = write_keys(tmp_path, "other")
    anchor_file = tmp_path / "other.json"
    export(db, other_private, anchor_file)
    done = verify_cli(db, keys[1], anchor_file)
    assert done.returncode == 1
    assert f"anchor {anchor_file}: signature by key" in done.stderr
    assert "not by the trusted key" in done.stderr


@pytest.mark.parametrize(("field", "value"), [("seq", 12), ("hash", "ab" * 32),
                                              ("anchored_at_ns", 1)])
def test_edited_anchor_file_fails_its_signature(tmp_path: Path, db: Path,
                                                keys: tuple[Path, Path], field: str,
                                                value: object) -> None:
    anchor_file = tmp_path / "a.json"
    export(db, keys[0], anchor_file)
    document = json.loads(anchor_file.read_text())
    assert document[field] != value
    document[field] = value
    anchor_file.write_text(json.dumps(document))
    done = verify_cli(db, keys[1], anchor_file)
    assert done.returncode == 1
    assert f"anchor {anchor_file}: signature does not match" in done.stderr


def test_malformed_and_unreadable_anchor_files(tmp_path: Path, db: Path,
                                               keys: tuple[Path, Path]) -> None:
    garbage = tmp_path / "garbage.json"
    garbage.write_text("{not json")
    done = verify_cli(db, keys[1], garbage)
    assert done.returncode == 1
    assert f"anchor {garbage}: not an anchor file" in done.stderr

    missing = tmp_path / "missing.json"
    done = verify_cli(db, keys[1], missing)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        f"error: cannot read anchor {missing}: No such file or directory"]

    done = run("verify", "--db", url(db), "--anchor", str(garbage))
    assert done.returncode == 2 and "--public-key" in done.stderr


# -- the service API -------------------------------------------------------------------------------
def api_anchor(db: Path, key: Ed25519PrivateKey, path: Path) -> None:
    with FaultLedger.open(url(db), background=False) as ledger:
        path.write_bytes(anchors.make_anchor(ledger, key).to_json())


def api_verify(db: Path, key: Ed25519PrivateKey, *paths: Path
               ) -> tuple[anchors.AnchorReport, list[str], int | None, bool]:
    with FaultLedger.open(url(db), background=False) as ledger:
        checked = anchors.verify_anchors(ledger, paths, key.public_key())
        combined = anchors.with_anchors(ledger.verify(), checked)
    return checked, combined.problems, combined.first_bad_seq, combined.ok


def test_broken_chain_below_an_anchor_is_reported_once(tmp_path: Path, db: Path) -> None:
    key = Ed25519PrivateKey.generate()
    api_anchor(db, key, tmp_path / "a.json")
    (payload,) = stored(db, "SELECT payload FROM events WHERE seq = 5")[0]
    tamper(db, ("UPDATE events SET payload = ? WHERE seq = 5",
                (str(payload).replace("step", "STEP"),)))
    checked, problems, first_bad, ok = api_verify(db, key, tmp_path / "a.json")
    assert not ok and first_bad == 5 and checked.first_bad_seq == 5
    assert checked.matched == []
    assert problems.count("record 5 does not match its hash: it was edited, inserted or "
                          "moved") == 1


def test_matching_anchors_below_a_forgery_still_match(tmp_path: Path, db: Path) -> None:
    key = Ed25519PrivateKey.generate()
    first, second = tmp_path / f"a{LENGTH}.json", tmp_path / f"a{LENGTH + 4}.json"
    api_anchor(db, key, first)
    append_reports(db, 4)
    api_anchor(db, key, second)
    forge_description(db, LENGTH + 2)
    checked, _problems, first_bad, ok = api_verify(db, key, first, second)
    assert not ok and first_bad == LENGTH + 1
    assert [(m.path.name, m.anchor.seq) for m in checked.matched] == [(first.name, LENGTH)]


def test_make_anchor_refuses_a_broken_chain(db: Path) -> None:
    tamper(db, ("UPDATE events SET occurred_at_ns = occurred_at_ns + 1 WHERE seq = 4", ()))
    with FaultLedger.open(url(db), background=False) as ledger, pytest.raises(
            anchors.AnchorRefused, match="record 4 does not match its hash"):
        anchors.make_anchor(ledger, Ed25519PrivateKey.generate())


# -- output safety ---------------------------------------------------------------------------------
def test_export_never_overwrites_without_force(tmp_path: Path, db: Path,
                                               keys: tuple[Path, Path]) -> None:
    target = tmp_path / "anchor.json"
    target.write_text("precious")
    done = run("anchor", "--key", str(keys[0]), "--output", str(target), "--db", url(db))
    assert done.returncode == 2 and "exists" in done.stderr
    assert target.read_text() == "precious"
    forced = run("anchor", "--key", str(keys[0]), "--output", str(target), "--force",
                 "--db", url(db))
    assert forced.returncode == 0, forced.stderr
    assert json.loads(target.read_text())["seq"] == LENGTH
    assert stat.S_IMODE(target.stat().st_mode) == 0o640
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".anchor")] == []


def test_export_never_follows_a_symlink_at_the_target(tmp_path: Path, db: Path,
                                                      keys: tuple[Path, Path]) -> None:
    victim = tmp_path / "victim.txt"
    victim.write_text("do not touch")
    target = tmp_path / "anchor.json"
    target.symlink_to(victim)
    done = run("anchor", "--key", str(keys[0]), "--output", str(target), "--db", url(db))
    assert done.returncode == 2 and "exists" in done.stderr
    forced = run("anchor", "--key", str(keys[0]), "--output", str(target), "--force",
                 "--db", url(db))
    assert forced.returncode == 0, forced.stderr
    assert victim.read_text() == "do not touch"
    assert not target.is_symlink() and json.loads(target.read_text())["seq"] == LENGTH


def test_keygen_never_overwrites_or_follows(tmp_path: Path) -> None:
    victim = tmp_path / "victim.txt"
    victim.write_text("do not touch")
    private, public = tmp_path / "k.pem", tmp_path / "k.pub"
    private.symlink_to(victim)
    done = run("anchor", "keygen", "--private-key", str(private), "--public-key", str(public))
    assert done.returncode == 2 and "exists" in done.stderr
    assert not public.exists() and victim.read_text() == "do not touch"
    forced = run("anchor", "keygen", "--private-key", str(private), "--public-key",
                 str(public), "--force")
    assert forced.returncode == 0, forced.stderr
    assert not private.is_symlink() and victim.read_text() == "do not touch"
    assert stat.S_IMODE(private.stat().st_mode) == 0o600
    before = private.read_bytes()
    again = run("anchor", "keygen", "--private-key", str(private), "--public-key",
                str(tmp_path / "new.pub"))
    assert again.returncode == 2 and private.read_bytes() == before


# -- the periodic anchors of `serve` ---------------------------------------------------------------
@pytest.fixture
def serving(db: Path) -> Iterator[FaultLedger]:
    """A writing ledger as `serve` holds it."""
    with FaultLedger.open(url(db), policy=Policy(confirmation_threshold=-2,
                                                  healing_enabled=True, healing_threshold=2),
                          background=False) as ledger:
        yield ledger


def wait_for(condition: Callable[[], bool], timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return
        time.sleep(0.02)
    raise AssertionError("condition not reached in time")


def anchor_names(directory: Path) -> list[str]:
    return [p.name for p in anchors.anchor_files(directory)]


def test_scheduler_writes_when_the_head_moves_and_at_stop(tmp_path: Path, db: Path,
                                                          serving: FaultLedger) -> None:
    private, public = write_keys(tmp_path)
    directory = tmp_path / "anchors"
    directory.mkdir()
    scheduler = anchors.AnchorScheduler(serving, private, directory, interval_sec=0.05)
    scheduler.start()
    wait_for(lambda: len(anchor_names(directory)) == 1)
    time.sleep(0.3)  # several intervals, the head unchanged: no new file
    assert len(anchor_names(directory)) == 1
    assert anchor_names(directory)[0].endswith(f"-seq{LENGTH}.json")
    serving.report("WHEEL_SLIP", "FAILED", severity=1, source_id="/robot/wheel")
    wait_for(lambda: len(anchor_names(directory)) == 2)
    assert anchor_names(directory)[1].endswith(f"-seq{LENGTH + 1}.json")
    assert scheduler.alive
    scheduler.stop()
    assert not scheduler.alive
    assert len(anchor_names(directory)) == 2  # head unchanged since the last: nothing at stop
    for path in anchors.anchor_files(directory):
        assert stat.S_IMODE(path.stat().st_mode) == 0o640

    late = anchors.AnchorScheduler(serving, private, directory, interval_sec=3600)
    late.start()
    serving.report("WHEEL_SLIP", "PASSED", source_id="/robot/wheel")
    late.stop()  # the shutdown anchor, long before the first interval
    assert anchor_names(directory)[-1].endswith(f"-seq{LENGTH + 2}.json")
    with FaultLedger.open(url(db), background=False) as reader:
        checked = anchors.verify_anchors(reader, anchors.anchor_files(directory),
                                         anchors.load_public_key(public))
    assert checked.ok and [m.anchor.seq for m in checked.matched] == [
        LENGTH, LENGTH + 1, LENGTH + 2]


def test_scheduler_survives_failures_and_recovers(tmp_path: Path, db: Path,
                                                  serving: FaultLedger,
                                                  caplog: pytest.LogCaptureFixture) -> None:
    private, _ = write_keys(tmp_path)
    directory = tmp_path / "not-yet"  # missing: never created by the scheduler
    scheduler = anchors.AnchorScheduler(serving, private, directory, interval_sec=0.05)
    def warnings() -> list[logging.LogRecord]:
        return [r for r in caplog.records if r.name == "faultledger.service.anchors"]

    with caplog.at_level(logging.WARNING, logger="faultledger.service.anchors"):
        scheduler.start()
        wait_for(lambda: len(warnings()) >= 3)  # one line per attempt, the thread goes on
        assert scheduler.alive and not directory.exists()
        record = warnings()[0]
        assert record.levelno == logging.WARNING and record.exc_info is None
        assert record.getMessage().startswith(f"anchor not written to {directory}: cannot "
                                              "write")
        assert "\n" not in record.getMessage()
        directory.mkdir()
        wait_for(lambda: len(anchor_names(directory)) == 1)
        assert scheduler.alive
        # The database fails under it (not an anchor problem): still one line, still alive.
        tamper(db, ("ALTER TABLE events RENAME TO events_away", ()))
        wait_for(lambda: "no such table" in warnings()[-1].getMessage())
        assert scheduler.alive
        tamper(db, ("ALTER TABLE events_away RENAME TO events", ()))
        assert serving.report("WHEEL_SLIP", "FAILED", source_id="/robot/wheel").accepted
        wait_for(lambda: len(anchor_names(directory)) == 2)
    scheduler.stop()


def test_scheduler_refuses_to_anchor_a_changed_log_and_prunes(
        tmp_path: Path, db: Path, caplog: pytest.LogCaptureFixture) -> None:
    private, _ = write_keys(tmp_path)
    directory = tmp_path / "anchors"
    directory.mkdir()
    with FaultLedger.open(url(db), background=False) as ledger:
        scheduler = anchors.AnchorScheduler(ledger, private, directory, keep=2)
        first = scheduler.run_once()
        assert first is not None and first.name.endswith(f"-seq{LENGTH}.json")
        assert scheduler.run_once() is None  # nothing new
        for _ in range(3):
            ledger.report("WHEEL_SLIP", "FAILED", source_id="/robot/wheel")
            assert scheduler.run_once() is not None
            time.sleep(0.002)  # distinct milliseconds in the names
        assert [n.split("-seq")[1] for n in anchor_names(directory)] == [
            f"{LENGTH + 2}.json", f"{LENGTH + 3}.json"]
        forge_description(db, 3)  # a re-hashed forgery behind the running manager's back
        ledger.report("WHEEL_SLIP", "PASSED", source_id="/robot/wheel")
        with caplog.at_level(logging.WARNING, logger="faultledger.service.anchors"):
            assert scheduler.run_once() is None
        assert "no longer has the hash anchored before" in caplog.text
        assert len(anchor_names(directory)) == 2


def test_verify_checks_the_newest_anchor_of_the_configured_directory(
        tmp_path: Path, db: Path) -> None:
    private, public = write_keys(tmp_path)
    directory = tmp_path / "anchors"
    directory.mkdir()
    config = tmp_path / "faultledger.yaml"
    config.write_text(f"database:\n  url: {url(db)}\nanchors:\n  key: {private}\n"
                      f"  public_key: {public}\n  directory: {directory}\n"
                      "  interval_sec: 60\n  keep: 10\n")
    settings = load_settings(config).anchors
    assert (settings.key, settings.directory, settings.interval_sec) == (private, directory, 60)
    with FaultLedger.open(url(db), background=False) as ledger:
        scheduler = anchors.AnchorScheduler.from_settings(ledger, settings)
        assert scheduler is not None and scheduler.run_once() is not None
    done = run("verify", "--config", str(config))
    assert done.returncode == 0, done.stderr
    assert f"-seq{LENGTH}.json: seq {LENGTH}" in done.stdout
    forge_description(db, 3)  # the first report
    done = run("verify", "--config", str(config))
    assert done.returncode == 1 and "first bad seq: 1" in done.stdout


def test_anchor_settings_are_checked(tmp_path: Path) -> None:
    config = tmp_path / "bad.yaml"
    config.write_text("anchors:\n  interval_sec: 0\n  folder: x\n")
    with pytest.raises(ConfigError, match=r"anchors.interval_sec.*anchors.folder"):
        load_settings(config)
    assert load_settings(None).anchors.key is None


def test_scheduler_thread_is_not_left_behind(tmp_path: Path, serving: FaultLedger) -> None:
    private, _ = write_keys(tmp_path)
    before = {t.name for t in threading.enumerate()}
    scheduler = anchors.AnchorScheduler(serving, private, tmp_path, interval_sec=0.05)
    scheduler.start()
    assert "faultledger-anchors" in {t.name for t in threading.enumerate()} - before
    scheduler.stop()
    assert "faultledger-anchors" not in {t.name for t in threading.enumerate()}
