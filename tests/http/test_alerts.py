"""Alerts that arrive exactly once (issue 21 item 4, docs/alerts.md), with real processes:
`faultledger http` delivers the config's alert rules to a receiver on loopback (a threaded
http.server standing for the webhook, Slack or PagerDuty endpoint), across SIGTERM and kill -9
restarts, a receiver that is down for a minute, and the filters of a rule."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Callable, Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest
from rich.cells import cell_len

from faultledger import FaultLedger
from tests.http.alert_receiver import AlertReceiver, alert_receiver
from tests.http.conftest import Server, write_config
from tests.http.test_auth_and_stream import bearer, token
from tests.http.test_fleet_api import PUSH, body
from tests.test_fleet_central import records_of, robot_log
from tests.test_safe_output import SGR, run_in_terminal

CLI = [sys.executable, "-m", "faultledger.cli.main"]


@pytest.fixture
def receiver() -> Iterator[AlertReceiver]:
    with alert_receiver() as found:
        yield found


def rule(name: str, url: str, on: list[str], **extra: Any) -> dict[str, Any]:
    receiver: dict[str, Any] = {"type": extra.pop("type", "webhook"), "url": url}
    if "routing_key" in extra:
        receiver["routing_key"] = extra.pop("routing_key")
    return {"name": name, "on": on, "receiver": receiver, **extra}


def config_with(tmp_path: Path, *rules: dict[str, Any]) -> Path:
    return write_config(tmp_path / "config.yaml", extra={"alerts": list(rules)})


def failed(code: str, severity: int = 3, **extra: Any) -> dict[str, Any]:
    return {"fault_code": code, "event_type": "FAILED", "severity": severity,
            "source_id": "/test/alerts", **extra}


def post(server: Server, reports: list[dict[str, Any]]) -> None:
    answer = server.client.post("/api/v1/reports", json=reports)
    assert answer.status_code == 200, answer.text
    results = answer.json()["results"]
    assert all(r["accepted"] for r in results), results


def expected_keys(db: Path, rule_name: str, events: tuple[str, ...] = ("fault_confirmed",)
                  ) -> list[str]:
    """The keys the log calls for: one per announcement of those events, in seq order,
    derived by the ledger's own notifications_after (not by the deliverer)."""
    with FaultLedger.open(f"sqlite:///{db}", create=False, upgrade=False) as ledger:
        identity = ledger.identity
        assert identity is not None
        found = ledger.notifications_after(0, 100_000)
    return [f"{identity.ledger_id}:{n.seq}:{rule_name}" for n in found
            if n.event_type.value in events]


def alerts_json(server: Server, **params: Any) -> dict[str, Any]:
    answer = server.client.get("/api/v1/alerts", params=params)
    assert answer.status_code == 200, answer.text
    found: dict[str, Any] = answer.json()
    return found


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=60,
                          check=False)


def wait_until(check: Callable[[], bool], timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if check():
            return
        time.sleep(0.1)
    raise AssertionError(f"not within {timeout} s: {what}")


def burst(server: Server, first: int, count: int) -> None:
    """``count`` CRITICAL faults of distinct codes (each confirms at once), 100 a request."""
    codes = [f"BURST_{i:04d}" for i in range(first, first + count)]
    for start in range(0, count, 100):
        post(server, [failed(code) for code in codes[start:start + 100]])


# -- durability ------------------------------------------------------------------------------
def test_a_burst_across_a_sigterm_restart_delivers_every_key_exactly_once(
        tmp_path: Path, http_server: Callable[..., Server], receiver: AlertReceiver) -> None:
    receiver.delay = 0.002  # so the restart surely comes in the middle of the deliveries
    config = config_with(tmp_path, rule("hook", receiver.url, ["fault_confirmed"]))
    server = http_server(config=config)
    burst(server, 0, 500)
    receiver.wait_for(20)
    assert server.stop(signal.SIGTERM) == 0
    before = len(receiver.delivered())
    assert before < 500, "the restart came after every delivery"
    server = http_server(config=config)
    burst(server, 500, 500)
    expected = expected_keys(server.db, "hook")
    assert len(expected) == 1000
    receiver.wait_for(1000, timeout=90)
    time.sleep(1.0)  # a key sent twice would arrive now
    keys = receiver.keys()
    assert Counter(keys) == Counter(expected)
    assert keys == expected, "delivered out of seq order"
    assert all(r.body["idempotency_key"] == r.headers["idempotency-key"]
               for r in receiver.delivered())


def test_a_burst_across_kill_9_misses_no_key(
        tmp_path: Path, http_server: Callable[..., Server], receiver: AlertReceiver) -> None:
    """Twice only what was answered 2xx but not yet recorded when the process died."""
    receiver.delay = 0.002
    config = config_with(tmp_path, rule("hook", receiver.url, ["fault_confirmed"]))
    server = http_server(config=config)
    burst(server, 0, 500)
    receiver.wait_for(20)
    server.stop(signal.SIGKILL)
    killed_at = time.time()
    assert len(receiver.delivered()) < 500, "the kill came after every delivery"
    server = http_server(config=config)
    burst(server, 500, 500)
    expected = expected_keys(server.db, "hook")
    assert len(expected) == 1000
    receiver.wait_for(1000, timeout=90)
    wait_until(lambda: set(receiver.keys()) >= set(expected), 60, "every key delivered")
    time.sleep(1.0)
    delivered = receiver.delivered()
    counts = Counter(r.headers["idempotency-key"] for r in delivered)
    assert set(counts) == set(expected)
    twice = {key for key, count in counts.items() if count > 1}
    assert max(counts.values()) <= 2
    first_arrival = {r.headers["idempotency-key"]: r.at for r in reversed(delivered)}
    assert all(first_arrival[key] <= killed_at for key in twice), (
        "a key was sent twice that had not been delivered before the kill")
    assert len(twice) <= 50  # one sender's batch at most


def test_a_receiver_down_for_a_minute_gets_everything_afterwards_in_order(
        tmp_path: Path, http_server: Callable[..., Server], receiver: AlertReceiver) -> None:
    """Connections refused for 30 s, then 503 for 30 s: the head is retried with growing
    waits and nothing behind it is sent; `faultledger alerts` and GET /api/v1/alerts show
    it retrying meanwhile, with its attempts and the last error."""
    receiver.down()
    config = config_with(tmp_path, rule("hook", receiver.url, ["fault_confirmed"]))
    server = http_server(config=config)
    start = time.monotonic()
    post(server, [failed(f"DOWN_{i}") for i in range(5)])
    expected = expected_keys(server.db, "hook")
    assert len(expected) == 5

    def head() -> dict[str, Any]:
        listed = alerts_json(server, state="retrying")["deliveries"]
        return listed[0] if listed else {}

    wait_until(lambda: head().get("attempts", 0) >= 3, 20, "the head retried 3 times")
    assert head()["key"] == expected[0]
    assert "cannot reach the receiver" in head()["last_error"]
    listed = alerts_json(server)
    assert [d["state"] for d in listed["deliveries"]] == ["pending"] * 4 + ["retrying"]
    assert listed["rules"][0]["deliveries"]["retrying"] == 1
    assert listed["rules"][0]["oldest_undelivered_seconds"] > 0
    done = cli("alerts", "--json", "--db", str(server.db))
    assert done.returncode == 0, done.stderr
    seen = json.loads(done.stdout)["deliveries"]
    assert seen[-1]["state"] == "retrying" and seen[-1]["attempts"] >= 3
    assert "cannot reach the receiver" in seen[-1]["last_error"]
    table = cli("alerts", "--db", str(server.db))
    assert table.returncode == 0 and "retrying" in table.stdout
    assert "1 retrying" in table.stdout

    time.sleep(max(0.0, start + 30 - time.monotonic()))
    receiver.status = 503
    receiver.up()
    wait_until(lambda: "HTTP 503" in (head().get("last_error") or ""), 40, "a 503 recorded")
    time.sleep(max(0.0, start + 60 - time.monotonic()))
    receiver.status = 200
    receiver.wait_for(5, timeout=45)
    assert receiver.keys() == expected
    assert {r.headers["idempotency-key"] for r in receiver.received} == set(expected), (
        "a delivery behind the head was tried before the head")
    wait_until(lambda: [d["state"] for d in alerts_json(server)["deliveries"]]
               == ["delivered"] * 5, 10, "every 2xx recorded")
    final = alerts_json(server)["deliveries"]
    assert final[-1]["attempts"] > 3 and final[0]["attempts"] == 1
    assert final[-1]["lag_seconds"] >= 55


# -- receivers -------------------------------------------------------------------------------
def test_pagerduty_sees_trigger_acknowledge_resolve_per_episode(
        tmp_path: Path, http_server: Callable[..., Server], receiver: AlertReceiver) -> None:
    config = config_with(tmp_path, rule(
        "pager", receiver.url, ["fault_confirmed", "fault_acknowledged", "fault_cleared"],
        type="pagerduty", routing_key="R0UT1NG-key_01"))
    server = http_server(config=config)
    for _episode in (1, 2):
        post(server, [failed("PD_MOTOR", description="motor stalled")])
        answer = server.client.post("/api/v1/faults/PD_MOTOR/ack", json={"note": "on it"})
        assert answer.status_code == 200, answer.text
        assert server.client.delete("/api/v1/faults/PD_MOTOR").status_code == 204
    got = receiver.wait_for(6)
    time.sleep(0.5)
    assert len(receiver.delivered()) == 6
    identity = server.client.get("/health").json()
    ledger_id, robot_id = identity["ledger_id"], identity["robot_id"]
    assert [b.body["event_action"] for b in got] == ["trigger", "acknowledge", "resolve"] * 2
    assert [b.body["dedup_key"] for b in got] == (
        [f"{ledger_id}:PD_MOTOR:1"] * 3 + [f"{ledger_id}:PD_MOTOR:2"] * 3)
    first = got[0].body
    assert set(first) == {"routing_key", "event_action", "dedup_key", "payload"}
    assert first["routing_key"] == "R0UT1NG-key_01"
    payload = first["payload"]
    assert set(payload) == {"summary", "source", "severity", "timestamp", "custom_details"}
    assert payload["severity"] == "critical" and payload["source"] == robot_id
    assert "PD_MOTOR" in payload["summary"] and "motor stalled" in payload["summary"]
    assert datetime.fromisoformat(payload["timestamp"]).tzinfo is not None
    assert payload["custom_details"]["episode"] == 1
    assert got[3].body["payload"]["custom_details"]["episode"] == 2


def test_filters_shelving_and_the_webhook_and_slack_bodies(
        tmp_path: Path, http_server: Callable[..., Server], receiver: AlertReceiver) -> None:
    """codes and min_severity select; a shelved fault alerts nothing (also when it comes
    back), and alerts again once unshelved."""
    with alert_receiver() as slack:
        config = config_with(
            tmp_path,
            rule("hw", receiver.url, ["fault_confirmed", "fault_acknowledged", "fault_cleared"],
                 codes=["HW_*", "ARM_[LR]"], min_severity="ERROR"),
            rule("chat", slack.url, ["fault_confirmed"], type="slack", codes=["HW_MOTOR"]))
        server = http_server(config=config)
        post(server, [failed("HW_MOTOR", 2), failed("HW_FAN", 1), failed("LIDAR_DOWN", 3),
                      failed("ARM_L", 3), failed("ARM_X", 3)])
        answer = server.client.post("/api/v1/faults/HW_MOTOR/shelve",
                                    json={"for": "2h", "reason": "known"})
        assert answer.status_code == 200, answer.text
        assert server.client.delete("/api/v1/faults/HW_MOTOR").status_code == 204
        post(server, [failed("HW_MOTOR", 2)])  # back, still shelved: nothing
        assert server.client.post("/api/v1/faults/HW_MOTOR/unshelve").status_code == 200
        assert server.client.post("/api/v1/faults/HW_MOTOR/ack").status_code == 200
        got = receiver.wait_for(3)
        slack.wait_for(1)
        time.sleep(1.0)  # anything more would arrive now
        got, chatted = receiver.delivered(), slack.delivered()
    assert [(r.body["event"], r.body["fault_code"]) for r in got] == [
        ("fault_confirmed", "HW_MOTOR"), ("fault_confirmed", "ARM_L"),
        ("fault_acknowledged", "HW_MOTOR")]
    identity = server.client.get("/health").json()
    body = got[0].body
    assert set(body) == {"event", "fault_code", "severity", "status", "seq", "ledger_id",
                         "robot_id", "occurred_at", "idempotency_key"}
    assert body["severity"] == "ERROR" and body["status"] == "CONFIRMED"
    assert body["ledger_id"] == identity["ledger_id"]
    assert body["robot_id"] == identity["robot_id"]
    assert body["idempotency_key"] == f"{identity['ledger_id']}:{body['seq']}:hw"
    assert got[0].headers["idempotency-key"] == body["idempotency_key"]
    assert got[0].headers["content-type"] == "application/json"
    assert datetime.fromisoformat(body["occurred_at"]).tzinfo is not None
    assert got[2].body["status"] == "CONFIRMED" and got[2].body["seq"] > body["seq"]
    assert [r.body for r in chatted] == [
        {"text": f"fault_confirmed: HW_MOTOR ERROR CONFIRMED on {identity['robot_id']}"}]


def test_a_4xx_fails_that_delivery_for_good_and_the_next_ones_go_on(
        tmp_path: Path, http_server: Callable[..., Server], receiver: AlertReceiver) -> None:
    receiver.status = 400
    config = config_with(tmp_path, rule("hook", receiver.url, ["fault_confirmed"]))
    server = http_server(config=config)
    post(server, [failed("REFUSED_1")])
    wait_until(lambda: bool(alerts_json(server, state="failed")["deliveries"]), 20,
               "the delivery failed")
    receiver.status = 200
    post(server, [failed("ACCEPTED_2")])
    receiver.wait_for(1)
    wait_until(lambda: bool(alerts_json(server, state="delivered")["deliveries"]), 10,
               "the 2xx recorded")
    listed = alerts_json(server)["deliveries"]
    assert [(d["fault_code"], d["state"], d["attempts"]) for d in listed] == [
        ("ACCEPTED_2", "delivered", 1), ("REFUSED_1", "failed", 1)]
    assert listed[1]["last_error"].startswith("HTTP 400 Bad Request")
    assert [r.answered for r in receiver.received] == [400, 200]
    metrics = server.client.get("/metrics").text
    assert 'faultledger_alert_deliveries{rule="hook",state="failed"} 1.0' in metrics
    assert 'faultledger_alert_deliveries{rule="hook",state="delivered"} 1.0' in metrics


# -- derived events --------------------------------------------------------------------------
def test_a_flood_alerts_once_at_the_eleventh_confirmation_of_a_window(
        tmp_path: Path, http_server: Callable[..., Server], receiver: AlertReceiver) -> None:
    config = config_with(tmp_path, rule("flood", receiver.url, ["flood"], codes=["FLOOD_*"]))
    server = http_server(config=config)
    now = datetime.now(UTC)
    window = now.replace(minute=now.minute - now.minute % 10, second=0, microsecond=0)
    at = (window + timedelta(seconds=1)).isoformat()
    post(server, [failed(f"FLOOD_{i:02d}", occurred_at=at) for i in range(10)]
         + [failed("OTHER_1", occurred_at=at)])
    post(server, [failed(f"FLOOD_{i:02d}", occurred_at=at) for i in range(10, 14)])
    got = receiver.wait_for(1)
    time.sleep(1.0)
    assert len(receiver.delivered()) == 1
    body = got[0].body
    assert len(expected_keys(server.db, "flood")) == 15  # OTHER_1's is not counted
    assert body["event"] == "flood" and body["fault_code"] == "FLOOD_10"
    assert body["idempotency_key"] == f"{body['ledger_id']}:{body['seq']}:flood:flood"
    assert body["details"]["confirmations"] == 11
    assert body["details"]["window_start"] == window.isoformat()


def test_a_fault_confirmed_for_24_hours_is_stale_once(
        tmp_path: Path, http_server: Callable[..., Server], receiver: AlertReceiver) -> None:
    config = config_with(tmp_path, rule("old", receiver.url, ["fault_confirmed", "stale"]))
    server = http_server(config=config)
    then = datetime.now(UTC) - timedelta(hours=25)
    post(server, [failed("OLD_FAULT", occurred_at=then.isoformat()),
                  failed("NEW_FAULT")])
    got = receiver.wait_for(3, timeout=30)
    time.sleep(6.0)  # a second check would alert again now
    assert len(receiver.delivered()) == 3
    assert [(r.body["event"], r.body["fault_code"]) for r in got] == [
        ("fault_confirmed", "OLD_FAULT"), ("fault_confirmed", "NEW_FAULT"),
        ("stale", "OLD_FAULT")]
    stale = got[2].body
    assert stale["seq"] == got[0].body["seq"]
    assert stale["idempotency_key"] == f"{stale['ledger_id']}:{stale['seq']}:old:stale"
    assert datetime.fromisoformat(stale["occurred_at"]) == then  # confirmed since then


def test_a_robot_log_lagging_at_a_central_alerts_once(
        tmp_path: Path, http_server: Callable[..., Server], receiver: AlertReceiver) -> None:
    """A robot that pushed its log and then went silent: once its lag passes the rule's
    sync_lag_seconds, one sync_lag alert names the robot, its log and how far it is held."""
    config = config_with(tmp_path, rule("lag", receiver.url, ["sync_lag", "fault_confirmed"],
                                        sync_lag_seconds=2))
    server = http_server(config=config)
    robot_id, ledger_id, records = records_of(robot_log(tmp_path / "robot.db", "robot-l", 6))
    answer = server.client.post(PUSH, json=body(robot_id, ledger_id, records, records[-1].seq))
    assert answer.status_code == 200, answer.text
    got = receiver.wait_for(1, timeout=20)
    time.sleep(6.0)  # the next check finds it still lagging: no second alert
    assert len(receiver.delivered()) == 1
    alert = got[0].body
    assert (alert["event"], alert["robot_id"], alert["ledger_id"], alert["seq"]) == (
        "sync_lag", robot_id, ledger_id, records[-1].seq)
    assert alert["fault_code"] is None and alert["severity"] is None
    assert alert["idempotency_key"].startswith(f"{ledger_id}:{records[-1].seq}:lag:sync_lag:")
    assert alert["details"]["threshold_seconds"] == 2


def test_the_alerts_table_fits_80_columns(
        tmp_path: Path, http_server: Callable[..., Server], receiver: AlertReceiver) -> None:
    receiver.status = 404
    config = config_with(tmp_path, rule("oncall-critical-robots", receiver.url,
                                        ["fault_confirmed"]))
    server = http_server(config=config)
    post(server, [failed("HW_LEFT_ARM_SHOULDER_JOINT_EMERGENCY_STOP")])
    wait_until(lambda: bool(alerts_json(server, state="failed")["deliveries"]), 20, "failed")
    server.stop()
    code, raw = run_in_terminal("alerts", "--db", str(server.db), columns=80)
    assert code == 0
    lines = SGR.sub("", raw.decode()).splitlines()
    assert max(cell_len(line) for line in lines) <= 80, "\n".join(lines)
    shown = "\n".join(lines)
    for words in ("failed", "HTTP 404", "oncall", "confirmed", "1 failed"):
        assert words in shown, shown


def test_the_listing_needs_the_read_permission_and_refuses_bad_filters(
        tmp_path: Path, http_server: Callable[..., Server]) -> None:
    tokens = tmp_path / "tokens.yaml"
    viewer, reporter = token(tokens, "wall", "viewer"), token(tokens, "plc", "reporter")
    server = http_server(config=write_config(tmp_path / "c.yaml",
                                             http={"tokens_file": str(tokens)}))
    assert server.client.get("/api/v1/alerts").status_code == 401
    assert server.client.get("/api/v1/alerts", headers=bearer(reporter)).status_code == 403
    answer = server.client.get("/api/v1/alerts", headers=bearer(viewer))
    assert answer.status_code == 200 and answer.json() == {"rules": [], "deliveries": []}
    refused = server.client.get("/api/v1/alerts", params={"state": "done"},
                                headers=bearer(viewer))
    assert refused.status_code == 400
    assert refused.json()["message"] == ("unknown state 'done'; the states are pending, "
                                         "retrying, delivered, failed")
    assert server.client.get("/api/v1/alerts", params={"limit": 0},
                             headers=bearer(viewer)).status_code in (400, 422)


def test_two_servers_on_one_database_deliver_each_rule_from_one_of_them(
        tmp_path: Path, http_server: Callable[..., Server], receiver: AlertReceiver) -> None:
    """The first server holds the rule's lease; reports made through the second are
    delivered by the first, once. When the first stops, the second takes the rule over."""
    config = config_with(tmp_path, rule("hook", receiver.url, ["fault_confirmed"]))
    first = http_server(config=config)
    second = http_server(config=config, db=first.db)
    [state] = alerts_json(second)["rules"]
    assert state["holder"].split(":")[1] == str(first.process.pid)
    post(second, [failed(f"TWO_{i:03d}") for i in range(100)])
    receiver.wait_for(100)
    assert first.stop() == 0
    wait_until(lambda: (alerts_json(second)["rules"][0]["holder"] or "").split(":")[1:2]
               == [str(second.process.pid)], 15, "the second server took the rule over")
    post(second, [failed(f"TWO_{i:03d}") for i in range(100, 150)])
    receiver.wait_for(150)
    time.sleep(1.0)
    expected = expected_keys(second.db, "hook")
    assert len(expected) == 150
    assert receiver.keys() == expected


def test_a_read_only_server_delivers_nothing(
        tmp_path: Path, http_server: Callable[..., Server], receiver: AlertReceiver) -> None:
    """Its writer's process delivers: a read-only server takes no rule."""
    http_server().stop()  # the database, made by a writer
    config = config_with(tmp_path, rule("hook", receiver.url, ["fault_confirmed"]))
    server = http_server("--read-only", config=config)
    assert "alerts:" not in server.output()
    assert alerts_json(server) == {"rules": [], "deliveries": []}
