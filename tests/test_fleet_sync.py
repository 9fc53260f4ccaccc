"""The robot side of store and forward (docs/fleet.md, "Robot side"): `faultledger sync`
pushes a robot's log into a real central (`faultledger http` on PostgreSQL or a SQLite file)
and `verify --central` compares the central's copy with the log.

Real processes, real files, a real central; the robot's log is tampered with through sqlite3
as an intruder would."""

from __future__ import annotations

import contextlib
import http.server
import json
import signal
import sqlite3
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
import yaml

from faultledger import FaultLedger
from faultledger.domain.integrity import record_hash
from faultledger.errors import ConfigError
from faultledger.fleet.client import check_central_url, read_token, retry_after_seconds
from faultledger.fleet.push import record_json
from faultledger.store.event_log import StoredRecord
from tests.fleet_central import (
    CLI,
    Central,
    add_reports,
    robot_hashes,
    robot_log,
    robot_token,
    run_cli,
    start_sync,
    sync,
    wait_for,
)
from tests.pg_server import PostgresServer, free_port


@pytest.fixture
def central(tmp_path: Path) -> Iterator[Central]:
    """A central on a SQLite file."""
    started = Central.start(tmp_path / "central", str(tmp_path / "central" / "central.db"))
    yield started
    started.stop()


def speed(text: str) -> str:
    return next((line for line in text.splitlines() if line.startswith("caught up")), text)


# -- the main scenario, on PostgreSQL --------------------------------------------------------
def test_a_log_of_thousands_reaches_a_postgresql_central_chain_for_chain(
        tmp_path: Path, postgres: PostgresServer) -> None:
    central = Central.start(tmp_path / "central", postgres.database("central"))
    try:
        robot = tmp_path / "robot.db"
        robot_id, ledger_id = robot_log(robot, 5000)
        token = robot_token(central, robot_id, tmp_path / "robot.token")

        first = sync(robot, central, token)
        assert first.returncode == 0, first.stderr
        assert "caught up" in first.stdout and "pushed 5000 records" in first.stdout, first.stdout
        print(speed(first.stdout))  # the measured rate, for docs/performance.md
        assert central.hashes(ledger_id) == robot_hashes(robot)
        (chain,) = central.robots()
        assert (chain["robot_id"], chain["ledger_id"], chain["last_seq"]) == (
            robot_id, ledger_id, 5000)

        again = sync(robot, central, token)
        assert again.returncode == 0, again.stderr
        assert "nothing to push, it held them all" in again.stdout
        assert central.hashes(ledger_id) == robot_hashes(robot)

        checked = run_cli("verify", "--db", str(robot), "--central", central.url,
                          "--token-file", str(token))
        assert checked.returncode == 0, checked.stderr
        assert (f"central {central.url}: its 5000 records of this log (seq 1..5000) are in "
                "this log, unchanged") in checked.stdout
    finally:
        central.stop()


# -- runs that end badly ---------------------------------------------------------------------
def test_a_sync_killed_mid_batch_loses_and_doubles_nothing(tmp_path: Path,
                                                          central: Central) -> None:
    robot = tmp_path / "robot.db"
    robot_id, ledger_id = robot_log(robot, 20_000)
    token = robot_token(central, robot_id, tmp_path / "robot.token")
    kills = []
    for number in range(3):
        before = central.last_seq(ledger_id)
        running = start_sync(robot, central.url, token, tmp_path / f"sync-{number}.log")
        # Killed as soon as the central has taken a batch more: the next one is in flight.
        assert wait_for(lambda b=before: central.last_seq(ledger_id) > b, 30, 0.01)
        running.send_signal(signal.SIGKILL)
        running.wait(10)
        kills.append(central.last_seq(ledger_id))
    assert kills[-1] < 20_000, "the syncs were too fast to be killed mid-way"
    done = sync(robot, central, token)
    assert done.returncode == 0, done.stderr
    held = central.hashes(ledger_id)
    assert [seq for seq, _ in held] == list(range(1, 20_001))  # none lost, none doubled
    assert held == robot_hashes(robot)


def test_a_central_that_is_away_is_named_and_exit_is_1(tmp_path: Path) -> None:
    robot = tmp_path / "robot.db"
    robot_log(robot, 10)
    token = tmp_path / "robot.token"
    token.write_text("flt_anything\n")
    port = free_port()
    started = time.monotonic()
    done = run_cli("sync", "--db", str(robot), "--central", f"http://127.0.0.1:{port}",
                   "--token-file", str(token))
    assert done.returncode == 1, done.stdout + done.stderr
    assert (f"error: cannot reach the central http://127.0.0.1:{port}/: connection refused"
            in done.stderr), done.stderr
    assert time.monotonic() - started < 15


def test_follow_waits_for_the_central_pushes_when_it_is_back_and_exits_0_on_sigterm(
        tmp_path: Path) -> None:
    robot = tmp_path / "robot.db"
    robot_id, ledger_id = robot_log(robot, 1200)
    port = free_port()
    central = Central("", str(tmp_path / "central.db"), tmp_path / "central",
                      tmp_path / "central" / "tokens.yaml", f"127.0.0.1:{port}")
    central.directory.mkdir()
    central.admin = central.token("supervisor", "admin")
    token = robot_token(central, robot_id, tmp_path / "robot.token")
    log = tmp_path / "follow.log"
    follower = start_sync(robot, f"http://127.0.0.1:{port}", token, log, "--follow")
    try:
        assert wait_for(lambda: "connection refused" in log.read_text(), 10), log.read_text()
        time.sleep(2)  # away a little longer: the follower backs off
        assert follower.poll() is None
        central.run()
        # Back: the backlog arrives within the backoff (at most a few seconds here).
        assert wait_for(lambda: central.last_seq(ledger_id) == 1200, 20), log.read_text()
        assert "takes records again" in log.read_text()
        # A new record reaches the central within a second of its commit.
        with FaultLedger.open(f"sqlite:///{robot}", robot_id=robot_id) as ledger:
            committed = time.monotonic()
            add_reports(ledger, 1, "NEW")
        assert wait_for(lambda: central.last_seq(ledger_id) == 1201, 5, 0.02)
        assert time.monotonic() - committed < 1.5
        follower.send_signal(signal.SIGTERM)
        assert follower.wait(10) == 0, log.read_text()
        assert "stopped (SIGTERM); the central holds seq 1201 of 1201" in log.read_text()
        assert central.hashes(ledger_id) == robot_hashes(robot)
    finally:
        if follower.poll() is None:
            follower.kill()
        central.stop()


def test_follow_contacts_an_idle_central_every_5_s_and_recovers_from_a_restored_central(
        tmp_path: Path, central: Central) -> None:
    """A central restored from an older backup answers chain-gap: the follower pushes again
    from the central's last seq."""
    robot = tmp_path / "robot.db"
    robot_id, ledger_id = robot_log(robot, 300)
    token = robot_token(central, robot_id, tmp_path / "robot.token")
    assert sync(robot, central, token).returncode == 0
    central.stop()
    backup = Path(central.db).with_name("backup.db")
    with contextlib.closing(sqlite3.connect(central.db)) as source, \
            contextlib.closing(sqlite3.connect(backup)) as target:
        source.backup(target)
    central.run()
    with FaultLedger.open(f"sqlite:///{robot}", robot_id=robot_id) as ledger:
        add_reports(ledger, 700, "LATER")
    log = tmp_path / "follow.log"
    follower = start_sync(robot, central.url, token, log, "--follow")
    try:
        assert wait_for(lambda: central.last_seq(ledger_id) == 1000, 20), log.read_text()
        first = {r["ledger_id"]: r for r in central.robots()}[ledger_id]["last_pushed_at"]
        time.sleep(6)  # idle: one contact at least, which the central records
        assert {r["ledger_id"]: r for r in central.robots()}[ledger_id]["last_pushed_at"] > first
        central.stop()
        Path(central.db).unlink()
        for suffix in ("-wal", "-shm"):
            Path(central.db + suffix).unlink(missing_ok=True)
        backup.rename(central.db)  # the central now holds seq 300 only
        central.run()
        with FaultLedger.open(f"sqlite:///{robot}", robot_id=robot_id) as ledger:
            add_reports(ledger, 5, "AFTER_RESTORE")
        assert wait_for(lambda: central.last_seq(ledger_id) == 1005, 40), log.read_text()
        assert central.hashes(ledger_id) == robot_hashes(robot)
        follower.send_signal(signal.SIGINT)
        assert follower.wait(10) == 0, log.read_text()
    finally:
        if follower.poll() is None:
            follower.kill()


def test_a_record_edited_before_it_was_pushed_is_named_and_nothing_after_it_is_pushed(
        tmp_path: Path, central: Central) -> None:
    robot = tmp_path / "robot.db"
    robot_id, ledger_id = robot_log(robot, 2500)
    token = robot_token(central, robot_id, tmp_path / "robot.token")
    with contextlib.closing(sqlite3.connect(robot)) as conn:
        conn.execute("UPDATE events SET payload = replace(payload, 'report ', 'REPORT ') "
                     "WHERE seq = 1457")
        assert conn.total_changes == 1
        conn.commit()
    done = sync(robot, central, token)
    assert done.returncode == 1, done.stdout + done.stderr
    assert ("refused the batch at seq 1457 (422 broken-chain: record 1457 does not match its "
            "hash") in done.stderr, done.stderr
    assert "the central holds seq 1456 of 2500" in done.stderr
    # Everything before it is witnessed; nothing from it on, and a second run changes nothing.
    assert central.hashes(ledger_id) == robot_hashes(robot)[:1456]
    again = sync(robot, central, token)
    assert again.returncode == 1 and "at seq 1457" in again.stderr
    assert central.last_seq(ledger_id) == 1456


def test_a_record_deleted_from_the_log_stops_the_push_naming_it(tmp_path: Path,
                                                                central: Central) -> None:
    robot = tmp_path / "robot.db"
    robot_id, ledger_id = robot_log(robot, 40)
    token = robot_token(central, robot_id, tmp_path / "robot.token")
    with contextlib.closing(sqlite3.connect(robot)) as conn:
        conn.execute("DELETE FROM events WHERE seq = 25")
        conn.commit()
    done = sync(robot, central, token)
    assert done.returncode == 1
    assert "record seq 25 is missing from the log" in done.stderr, done.stderr
    assert central.last_seq(ledger_id) == 24


def test_a_token_of_another_robot_is_refused_403_and_a_revoked_one_401(
        tmp_path: Path, central: Central) -> None:
    robot = tmp_path / "robot.db"
    robot_log(robot, 20, "robot-a")
    other = robot_token(central, "robot-b", tmp_path / "robot-b.token")
    done = sync(robot, central, other)
    assert done.returncode == 1
    assert f"error: the central {central.url} refused the token (403 forbidden: token " \
           "'robot-b' may push only" in done.stderr, done.stderr
    assert run_cli("token", "revoke", "robot-b", "--file", str(central.tokens)).returncode == 0
    assert wait_for(lambda: sync(robot, central, other).returncode == 1 and "401" in sync(
        robot, central, other).stderr, 10, 0.5)


def test_bad_options_are_exit_2_in_one_line(tmp_path: Path) -> None:
    robot = tmp_path / "robot.db"
    robot_log(robot, 3)
    token = tmp_path / "robot.token"
    token.write_text("flt_x\n")
    cases = {
        ("--central", "ftp://central", "--token-file", str(token)): "must be http://",
        ("--central", "http://127.0.0.1:1"): "no token: give --token-file FILE",
        ("--token-file", str(token)): "no central: give --central URL",
        ("--central", "http://127.0.0.1:1", "--token-file", str(tmp_path / "none")):
            "cannot read token file",
    }
    for args, expected in cases.items():
        done = run_cli("sync", "--db", str(robot), *args)
        assert done.returncode == 2, (args, done.stderr)
        assert expected in done.stderr and len(done.stderr.strip().splitlines()) == 1, \
            done.stderr
    missing = run_cli("sync", "--db", str(tmp_path / "absent.db"), "--central",
                      "http://127.0.0.1:1", "--token-file", str(token))
    assert missing.returncode == 2 and not (tmp_path / "absent.db").exists()


def test_an_empty_log_has_nothing_to_push(tmp_path: Path, central: Central) -> None:
    robot = tmp_path / "robot.db"
    assert run_cli("db", "upgrade", "--db", str(robot)).returncode == 0
    token = robot_token(central, "robot-a", tmp_path / "robot.token")
    done = sync(robot, central, token)
    assert done.returncode == 0, done.stderr
    assert "nothing to push: the log" in done.stdout and "is empty" in done.stdout


# -- a central behind a proxy that answers 503 -----------------------------------------------
class Proxy:
    """A reverse proxy in front of the central (as nginx would be): the first ``refuse``
    requests are answered 503 with ``Retry-After``, the others forwarded."""

    def __init__(self, target: str, refuse: int, retry_after: str) -> None:
        self.target = target
        self.refuse = refuse
        self.retry_after = retry_after
        self.seen: list[float] = []
        proxy = self

        class Handler(http.server.BaseHTTPRequestHandler):
            def log_message(self, *_: object) -> None:
                pass

            def _answer(self) -> None:
                proxy.seen.append(time.monotonic())
                length = int(self.headers.get("content-length") or 0)
                body = self.rfile.read(length) if length else b""
                if len(proxy.seen) <= proxy.refuse:
                    self.send_response(503)
                    self.send_header("retry-after", proxy.retry_after)
                    self.send_header("content-length", "0")
                    self.end_headers()
                    return
                answer = httpx.request(self.command, proxy.target + self.path.lstrip("/"),
                                       content=body, headers={
                                           k: v for k, v in self.headers.items()
                                           if k.lower() in ("authorization", "content-type")})
                self.send_response(answer.status_code)
                self.send_header("content-type", "application/json")
                self.send_header("content-length", str(len(answer.content)))
                self.end_headers()
                self.wfile.write(answer.content)

            do_GET = _answer
            do_POST = _answer

        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/"
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


def test_a_503_with_retry_after_is_waited_out(tmp_path: Path, central: Central) -> None:
    robot = tmp_path / "robot.db"
    robot_id, ledger_id = robot_log(robot, 50)
    token = robot_token(central, robot_id, tmp_path / "robot.token")
    proxy = Proxy(central.url, refuse=2, retry_after="2")
    try:
        done = sync(robot, central, token, url=proxy.url)
    finally:
        proxy.close()
    assert done.returncode == 0, done.stderr
    assert "503" in done.stderr and "trying again in 2 s" in done.stderr
    assert proxy.seen[1] - proxy.seen[0] >= 1.9 and proxy.seen[2] - proxy.seen[1] >= 1.9
    assert central.hashes(ledger_id) == robot_hashes(robot)


def test_a_central_busy_for_longer_ends_a_single_sync_with_exit_1(
        tmp_path: Path, central: Central) -> None:
    robot = tmp_path / "robot.db"
    robot_id, _ = robot_log(robot, 5)
    token = robot_token(central, robot_id, tmp_path / "robot.token")
    proxy = Proxy(central.url, refuse=100, retry_after="3600")
    try:
        done = sync(robot, central, token, url=proxy.url)
    finally:
        proxy.close()
    assert done.returncode == 1
    assert f"the central {proxy.url} cannot take records now (503" in done.stderr, done.stderr


# -- verify --central ------------------------------------------------------------------------
def rechain(path: Path, seq: int, description: str) -> None:
    """Rewrite record ``seq``'s description and recompute every hash from it on, the way an
    intruder who knows the hash function would: the log then verifies on its own."""
    with contextlib.closing(sqlite3.connect(path)) as conn:
        rows = conn.execute("SELECT seq, event_id, kind, fault_code, source_id, payload, "
                            "occurred_at_ns, recorded_at_ns, schema_version, hash FROM events "
                            "WHERE seq >= ? - 1 ORDER BY seq", (seq,)).fetchall()
        previous = rows[0][9]
        for row in rows[1:]:
            payload = row[5]
            if row[0] == seq:
                data = json.loads(payload)
                data["description"] = description
                payload = json.dumps(data, sort_keys=True, separators=(",", ":"),
                                     ensure_ascii=False)
            previous = record_hash(previous, row[0], row[1], row[2], row[3], row[4], payload,
                                   row[6], row[7], row[8])
            conn.execute("UPDATE events SET payload = ?, hash = ? WHERE seq = ?",
                         (payload, previous, row[0]))
        conn.execute("UPDATE checkpoints SET hash = ? WHERE seq = ?", (previous, rows[-1][0]))
        conn.commit()


def test_verify_central_names_the_first_seq_of_a_truncated_or_rewritten_log(
        tmp_path: Path, central: Central) -> None:
    robot = tmp_path / "robot.db"
    robot_id, _ = robot_log(robot, 1500)
    token = robot_token(central, robot_id, tmp_path / "robot.token")
    assert sync(robot, central, token).returncode == 0
    with FaultLedger.open(f"sqlite:///{robot}", robot_id=robot_id) as ledger:
        add_reports(ledger, 20, "NOT_PUSHED")

    def verify(path: Path, *extra: str) -> subprocess.CompletedProcess[str]:
        return run_cli("verify", "--db", str(path), "--central", central.url, "--token-file",
                       str(token), *extra)

    ok = verify(robot)
    assert ok.returncode == 0, ok.stderr
    assert "its 1500 records of this log (seq 1..1500) are in this log, unchanged; 20 newer " \
           "records not pushed yet" in ok.stdout
    as_json = json.loads(verify(robot, "--json").stdout)
    assert as_json["ok"] and as_json["central"]["compared"] == 1500

    rewritten = tmp_path / "rewritten.db"
    with contextlib.closing(sqlite3.connect(robot)) as source, \
            contextlib.closing(sqlite3.connect(rewritten)) as target:
        source.backup(target)
    rechain(rewritten, 777, "nothing happened here")
    alone = run_cli("verify", "--db", str(rewritten), "--from-seq", "1")
    assert alone.returncode == 0, alone.stdout + alone.stderr  # the chain checks on its own
    found = verify(rewritten)
    assert found.returncode == 1
    assert f"FAILED: central {central.url}: record seq 777 differs from the central's copy" \
           in found.stderr, found.stderr
    assert "first bad seq: 777" in found.stdout

    truncated = tmp_path / "truncated.db"
    with contextlib.closing(sqlite3.connect(robot)) as source, \
            contextlib.closing(sqlite3.connect(truncated)) as target:
        source.backup(target)
    with contextlib.closing(sqlite3.connect(truncated)) as conn:
        conn.execute("DELETE FROM events WHERE seq > 1200")
        conn.commit()
    cut = verify(truncated)
    assert cut.returncode == 1
    assert ("record seq 1201 is missing from this log: it ends at seq 1200, the central holds "
            "records up to seq 1500; the log was truncated") in cut.stderr, cut.stderr
    assert "first bad seq: 1201" in cut.stdout


def test_verify_central_names_the_robots_other_log_after_its_database_was_replaced(
        tmp_path: Path, central: Central) -> None:
    old = tmp_path / "old.db"
    robot_id, old_ledger = robot_log(old, 30)
    token = robot_token(central, robot_id, tmp_path / "robot.token")
    assert sync(old, central, token).returncode == 0
    new = tmp_path / "new.db"  # the disk was replaced: a new log of the same robot
    _, new_ledger = robot_log(new, 12, robot_id)
    assert sync(new, central, token).returncode == 0
    done = run_cli("verify", "--db", str(new), "--central", central.url, "--token-file",
                   str(token))
    assert done.returncode == 0, done.stderr
    assert (f"the central also holds 1 other log of robot {robot_id}, not in this database (it "
            f"was replaced since): ledger_id {old_ledger} (seq 1..30") in done.stdout, done.stdout
    as_json = json.loads(run_cli("verify", "--db", str(new), "--central", central.url,
                                 "--token-file", str(token), "--json").stdout)
    assert [log["ledger_id"] for log in as_json["central"]["other_logs"]] == [old_ledger]
    assert new_ledger != old_ledger
    alone = run_cli("verify", "--db", str(old), "--central", central.url, "--token-file",
                    str(token), "--json")
    assert [log["ledger_id"] for log in json.loads(alone.stdout)["central"]["other_logs"]] == [
        new_ledger]


def test_verify_central_that_is_away_fails_naming_it(tmp_path: Path) -> None:
    robot = tmp_path / "robot.db"
    robot_log(robot, 5)
    token = tmp_path / "robot.token"
    token.write_text("flt_x\n")
    port = free_port()
    done = run_cli("verify", "--db", str(robot), "--central", f"http://127.0.0.1:{port}",
                   "--token-file", str(token))
    assert done.returncode == 1
    assert "verify FAILED: cannot compare with the central: cannot reach the central " \
           f"http://127.0.0.1:{port}/: connection refused" in done.stderr, done.stderr


# -- `faultledger http` with the config's fleet: ---------------------------------------------
def test_http_with_fleet_config_pushes_each_new_record_within_a_second(
        tmp_path: Path, central: Central) -> None:
    robot = tmp_path / "robot.db"
    robot_id, ledger_id = robot_log(robot, 100)
    token = robot_token(central, robot_id, tmp_path / "robot.token")
    config = tmp_path / "robot.yaml"
    config.write_text(yaml.safe_dump({
        "robot_id": robot_id, "http": {"tokens_file": None},
        "fleet": {"central": central.url, "token_file": str(token)}}))
    log = tmp_path / "robot-http.log"
    with log.open("w") as out:
        server = subprocess.Popen(
            [*CLI, "http", "--db",
             str(robot), "--listen", "127.0.0.1:0", "--config", str(config)],
            stdout=out, stderr=subprocess.STDOUT, text=True, stdin=subprocess.DEVNULL)
    try:
        assert wait_for(lambda: "fleet: pushing this log to" in log.read_text(), 30), \
            log.read_text()
        url = log.read_text().split("ready: ", 1)[1].split(" ", 1)[0]
        assert wait_for(lambda: central.last_seq(ledger_id) == 100, 10), log.read_text()
        with httpx.Client(base_url=url, timeout=10) as web:
            for number in range(5):
                sent = time.monotonic()
                answer = web.post("/api/v1/reports", json={
                    "fault_code": f"HTTP_{number}", "event_type": "FAILED", "severity": 2,
                    "source_id": "/plc"}).json()
                assert answer["accepted"], answer
                assert wait_for(lambda s=int(answer["seq"]): central.last_seq(ledger_id) >= s,
                                5, 0.02)
                assert time.monotonic() - sent < 1.2
        server.send_signal(signal.SIGTERM)
        assert server.wait(15) == 0, log.read_text()
    finally:
        if server.poll() is None:
            server.kill()
    assert central.hashes(ledger_id) == robot_hashes(robot)


def test_http_refuses_to_start_with_an_unreadable_fleet_token_file(tmp_path: Path) -> None:
    config = tmp_path / "robot.yaml"
    config.write_text(yaml.safe_dump({"http": {"tokens_file": None}, "fleet": {
        "central": "http://127.0.0.1:1", "token_file": str(tmp_path / "missing.token")}}))
    done = run_cli("http", "--db", str(tmp_path / "robot.db"), "--listen", "127.0.0.1:0",
                   "--config", str(config), timeout=30)
    assert done.returncode == 2
    assert "cannot read token file" in done.stderr


# -- pieces --------------------------------------------------------------------------------
def test_the_token_file_holds_what_token_create_printed(tmp_path: Path) -> None:
    path = tmp_path / "t"
    path.write_text("# robot-a, made 2026-11-21\nflt_abc-DEF_123\n\n")
    assert read_token(path) == "flt_abc-DEF_123"
    for text, expected in [("", "is empty"), ("a b\n", "one token on one line"),
                           ("flt_a\nflt_b\n", "one token on one line"),
                           ("tokens:\n- name: x\n  sha256: ab\n", "a server's token file"),
                           ("flt_é\n", "not a token")]:
        path.write_text(text)
        with pytest.raises(ConfigError, match=expected):
            read_token(path)
    path.write_bytes(b"x" * 70_000)
    with pytest.raises(ConfigError, match="larger than 64 KiB"):
        read_token(path)


def test_central_urls_and_retry_after() -> None:
    assert check_central_url("http://c:8080") == "http://c:8080/"
    assert check_central_url("https://c/fl") == "https://c/fl/"
    for bad in ("c:8080", "ftp://c", "http://", "http://c/?x=1", "http://c:99999"):
        with pytest.raises(ConfigError):
            check_central_url(bad)
    assert retry_after_seconds("7") == 7.0
    assert retry_after_seconds("Wed, 21 Oct 2015 07:28:00 GMT", now=1445412470.0) == 10.0
    assert retry_after_seconds("soon") is None
    assert retry_after_seconds("99999999") == 3600.0


def test_a_record_is_sent_as_stored() -> None:
    record = StoredRecord(2, "e", "fault_reported", "C", "/s", '{"a":"ü"}', 1, 2, 1, "h" * 64,
                          "p" * 64)
    sent = json.loads(record_json(record))
    assert sent["payload"] == '{"a":"ü"}' and sent["prev_hash"] == "p" * 64
    assert set(sent) == {"seq", "event_id", "kind", "fault_code", "source_id", "payload",
                         "occurred_at_ns", "recorded_at_ns", "schema_version", "hash",
                         "prev_hash"}
