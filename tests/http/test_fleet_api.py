"""The central's routes through a real `faultledger http` (docs/fleet.md): a robot token pushes
only its own logs, refusals name the seq and store nothing, supervisors list the chains."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from tests.http.conftest import Server, write_config
from tests.http.test_tokens import bearer, create
from tests.test_fleet_central import records_of, robot_log

PUSH = "/api/v1/fleet/records"


def body(robot_id: str, ledger_id: str, records: list[Any], head: int) -> dict[str, Any]:
    return {"robot_id": robot_id, "ledger_id": ledger_id, "head_seq": head,
            "records": [{"seq": r.seq, "event_id": r.event_id, "kind": r.kind,
                         "fault_code": r.fault_code, "source_id": r.source_id,
                         "payload": r.payload, "occurred_at_ns": r.occurred_at_ns,
                         "recorded_at_ns": r.recorded_at_ns,
                         "schema_version": r.schema_version, "hash": r.hash,
                         "prev_hash": r.prev_hash} for r in records]}


def test_push_list_and_compare_with_role_checks(http_server: Callable[..., Server],
                                                tmp_path: Path) -> None:
    tokens = tmp_path / "tokens.yaml"
    robot_a = create(tokens, "robot-a", "robot")
    robot_b = create(tokens, "robot-b", "robot")
    viewer = create(tokens, "supervisor", "viewer")
    server = http_server(config=write_config(tmp_path / "c.yaml",
                                             http={"tokens_file": str(tokens)}))
    robot_id, ledger_id, records = records_of(robot_log(tmp_path / "a.db", "robot-a", 60))
    head = records[-1].seq

    stolen = server.client.post(PUSH, json=body(robot_id, ledger_id, records, head),
                                headers=bearer(robot_b))
    assert stolen.status_code == 403 and stolen.json()["error"] == "forbidden"
    by_viewer = server.client.post(PUSH, json=body(robot_id, ledger_id, records, head),
                                   headers=bearer(viewer))
    assert by_viewer.status_code == 403

    first = server.client.post(PUSH, json=body(robot_id, ledger_id, records[:40], head),
                               headers=bearer(robot_a))
    assert first.status_code == 200, first.text
    assert first.json() | {"last_hash": None} == {
        "robot_id": "robot-a", "ledger_id": ledger_id, "last_seq": 40, "last_hash": None,
        "stored": 40, "ignored": 0}

    edited = dict(body(robot_id, ledger_id, records[40:], head))
    edited["records"][3] = {**edited["records"][3],
                            "payload": edited["records"][3]["payload"].replace("d", "e", 1)}
    broken = server.client.post(PUSH, json=edited, headers=bearer(robot_a))
    assert broken.status_code == 422
    assert broken.json()["error"] == "broken-chain" and broken.json()["seq"] == 44

    gap = server.client.post(PUSH, json=body(robot_id, ledger_id, records[45:], head),
                             headers=bearer(robot_a))
    assert gap.status_code == 409
    assert (gap.json()["error"], gap.json()["last_seq"]) == ("chain-gap", 40)

    rest = server.client.post(PUSH, json=body(robot_id, ledger_id, records[40:], head),
                              headers=bearer(robot_a))
    assert rest.status_code == 200 and rest.json()["last_seq"] == head

    [item] = server.client.get("/api/v1/fleet/robots", headers=bearer(viewer)).json()["items"]
    assert {k: item[k] for k in ("robot_id", "ledger_id", "last_seq", "records")} == {
        "robot_id": "robot-a", "ledger_id": ledger_id, "last_seq": head, "records": head}
    assert item["last_hash"] == records[-1].hash and item["lag_seconds"] < 60
    # A robot's token lists that robot's logs only (verify --central names a replaced one).
    own = server.client.get("/api/v1/fleet/robots", headers=bearer(robot_a))
    assert own.status_code == 200
    assert [{**seen, "lag_seconds": 0} for seen in own.json()["items"]] == [
        {**item, "lag_seconds": 0}]
    others = server.client.get("/api/v1/fleet/robots", headers=bearer(robot_b))
    assert others.status_code == 200 and others.json() == {"items": []}

    own = server.client.get(PUSH, params={"ledger_id": ledger_id, "after_seq": 50},
                            headers=bearer(robot_a))
    assert own.status_code == 200
    assert [(i["seq"], i["hash"]) for i in own.json()["items"]] == [
        (r.seq, r.hash) for r in records[50:]]
    other = server.client.get(PUSH, params={"ledger_id": ledger_id}, headers=bearer(robot_b))
    assert other.status_code == 403


def test_malformed_batches_are_one_clear_400(http_server: Callable[..., Server],
                                             tmp_path: Path) -> None:
    server = http_server()
    cases: list[tuple[object, str]] = [
        ([], "must be a JSON object"),
        ({"robot_id": "r", "ledger_id": "x", "head_seq": 0}, "records is required"),
        ({"robot_id": "r!", "ledger_id": "00000000-0000-0000-0000-000000000000",
          "head_seq": 0, "records": []}, "robot_id must be"),
        ({"robot_id": "r", "ledger_id": "00000000-0000-0000-0000-000000000000",
          "head_seq": 0, "records": [{"seq": 1}]}, "record 0: event_id is required"),
        ({"robot_id": "r", "ledger_id": "00000000-0000-0000-0000-000000000000",
          "head_seq": 0, "records": [0] * 1001}, "at most 1000"),
    ]
    for sent, words in cases:
        answer = server.client.post(PUSH, content=json.dumps(sent),
                                    headers={"content-type": "application/json"})
        assert answer.status_code == 400, (sent, answer.text)
        assert words in answer.json()["message"], answer.json()
    assert server.client.get("/api/v1/fleet/robots").json() == {"items": []}


def test_metrics_give_each_robot_logs_lag(http_server: Callable[..., Server],
                                          tmp_path: Path) -> None:
    server = http_server()
    robot_id, ledger_id, records = records_of(robot_log(tmp_path / "a.db", "robot-a", 30))
    sent = server.client.post(PUSH, json=body(robot_id, ledger_id, records[:10],
                                              records[-1].seq))
    assert sent.status_code == 200, sent.text
    text = server.client.get("/metrics").text
    labels = f'{{ledger_id="{ledger_id}",robot_id="robot-a"}}'
    assert f"faultledger_fleet_records{labels} 10.0" in text
    assert f"faultledger_fleet_lag_records{labels} {float(records[-1].seq - 10)}" in text
    assert f"faultledger_fleet_lag_seconds{labels}" in text
    assert f"faultledger_fleet_unprojected_records{labels}" in text
    assert server.client.get("/api/v1/faults", params={"robot": "robot-a"}).status_code == 200
    projected = server.client.get("/metrics").text  # the read brought the projections up
    assert f"faultledger_fleet_unprojected_records{labels} 0.0" in projected
