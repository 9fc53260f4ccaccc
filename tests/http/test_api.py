"""The HTTP API through a real `faultledger http` process: medkit fault shapes, reports,
history, state-at, statistics, metrics and every error reason (docs/http.md)."""

from __future__ import annotations

import json
import subprocess
import sys
import uuid
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from prometheus_client.parser import text_string_to_metric_families

from tests.http.conftest import Server, start_server, write_config

ITEM_KEYS = {"description", "fault_code", "first_occurred", "last_occurred", "occurrence_count",
             "reporting_sources", "severity", "severity_label", "status"}


def cli(db: Path, *args: str) -> str:
    done = subprocess.run([sys.executable, "-m", "faultledger.cli.main", *args, "--db", str(db)],
                          capture_output=True, text=True, timeout=60, check=True)
    return done.stdout


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    folder = tmp_path_factory.mktemp("api")
    config = write_config(folder / "config.yaml", http={"max_body_bytes": 4096,
                                                          "max_reports_per_request": 5},
                          extra={"policy": {"confirmation_threshold": -3}})
    running = start_server(folder / "faults.db", config=config)
    yield running
    running.stop()


def post(server: Server, body: object) -> httpx.Response:
    return server.client.post("/api/v1/reports", json=body)


def report(server: Server, code: str, event_type: str = "FAILED", severity: int = 3,
           **extra: object) -> dict[str, object]:
    answer = post(server, {"fault_code": code, "event_type": event_type,
                           "severity": severity, "source_id": "/robot/arm", **extra})
    assert answer.status_code == 200, answer.text
    found: dict[str, object] = answer.json()
    return found


def test_reports_answer_per_report_and_repeat_idempotently(server: Server) -> None:
    event_id = str(uuid.uuid4())
    first = report(server, "API_DOOR", description="door open", event_id=event_id)
    assert first["accepted"] is True and first["duplicate"] is False
    assert isinstance(first["seq"], int) and first["event_id"] == event_id
    again = report(server, "API_DOOR", description="door open", event_id=event_id)
    assert again["accepted"] is True and again["duplicate"] is True
    assert again["reason"] == "duplicate"
    batch = post(server, [{"fault_code": "API_B1", "event_type": "FAILED", "severity": 1},
                          {"fault_code": "bad code", "event_type": "FAILED"},
                          {"fault_code": "API_B2", "event_type": "PASSED",
                           "occurred_at": "2026-11-23T10:00"}])
    assert batch.status_code == 200
    results = batch.json()["results"]
    assert [r["accepted"] for r in results] == [True, False, False]
    assert "invalid character ' '" in results[1]["message"]
    assert results[2]["message"].startswith("occurred_at needs a zone")
    one_bad = post(server, {"fault_code": "API_X", "event_type": "MAYBE"})
    assert one_bad.status_code == 400 and one_bad.json()["reason"] == "invalid"
    assert one_bad.json()["accepted"] is False


@pytest.mark.parametrize(("body", "message"), [
    ({"fault_code": "A", "event_type": "FAILED", "sevrity": 1}, "unknown field 'sevrity'"),
    ({"event_type": "FAILED"}, "fault_code is required"),
    ([], "the list of reports is empty"),
    ([{"fault_code": "A", "event_type": "FAILED"}, 3], "report 1: a report must be a JSON"),
    ([{"fault_code": f"A{i}", "event_type": "FAILED"} for i in range(6)], "6 reports in one"),
])
def test_malformed_report_bodies_are_400_and_store_nothing(server: Server, body: object,
                                                           message: str) -> None:
    before = server.client.get("/health").json()["last_seq"]
    answer = post(server, body)
    assert answer.status_code == 400
    assert answer.json()["reason"] == "invalid" and message in answer.json()["message"]
    assert server.client.get("/health").json()["last_seq"] == before


def test_bad_json_and_oversized_bodies(server: Server) -> None:
    answer = server.client.post("/api/v1/reports", content=b'{"fault_code":',
                                headers={"content-type": "application/json"})
    assert answer.status_code == 400
    assert answer.json()["message"] == "the request body is not valid JSON"
    big = server.client.post("/api/v1/reports", content=b"[" + b" " * 5000 + b"]",
                             headers={"content-type": "application/json"})
    assert big.status_code == 413 and big.json()["reason"] == "too_large"

    def chunks() -> Iterator[bytes]:
        yield b"["
        for _ in range(10):
            yield b" " * 1000
        yield b"]"

    streamed = server.client.post("/api/v1/reports", content=chunks(),
                                  headers={"content-type": "application/json"})
    assert streamed.status_code == 413 and streamed.json()["reason"] == "too_large"


def test_fault_list_and_detail_have_the_gateway_shapes(server: Server) -> None:
    report(server, "API_SHAPE", description="shape")
    listed = server.client.get("/api/v1/faults").json()
    assert set(listed) == {"items", "x-medkit"}
    assert listed["x-medkit"]["count"] == listed["x-medkit"]["total_count"] == len(
        listed["items"])
    item = next(i for i in listed["items"] if i["fault_code"] == "API_SHAPE")
    assert set(item) == ITEM_KEYS
    assert item["status"] == "CONFIRMED" and item["severity_label"] == "CRITICAL"
    assert isinstance(item["first_occurred"], float)
    detail = server.client.get("/api/v1/faults/API_SHAPE").json()
    assert detail["item"] == {"code": "API_SHAPE", "fault_name": "shape", "severity": 3,
                              "status": {"aggregatedStatus": "active", "confirmedDTC": "1",
                                         "pendingDTC": "0", "testFailed": "1"}}
    records = detail["environment_data"]["extended_data_records"]
    assert records["first_occurrence"].endswith("Z") and len(records["first_occurrence"]) == 24
    assert detail["x-medkit"]["status_raw"] == "CONFIRMED"
    assert detail["x-medkit"]["reporting_sources"] == ["/robot/arm"]
    scoped = server.client.get("/api/v1/apps/arm/faults").json()
    assert "API_SHAPE" in [i["fault_code"] for i in scoped["items"]]
    assert server.client.get("/api/v1/apps/arm/faults/API_SHAPE").status_code == 200
    assert server.client.get("/api/v1/apps/robot/faults/API_SHAPE").status_code == 404


def test_status_groups_and_invalid_values(server: Server) -> None:
    report(server, "API_PENDING", severity=1)  # PREFAILED: one FAILED of the three needed
    report(server, "API_GONE")
    assert server.client.delete("/api/v1/faults/API_GONE").status_code == 204

    def codes(status: str | None) -> set[str]:
        params = {} if status is None else {"status": status}
        return {i["fault_code"] for i in server.client.get("/api/v1/faults",
                                                            params=params).json()["items"]}

    assert "API_PENDING" in codes(None) and "API_PENDING" in codes("pending")
    assert "API_PENDING" not in codes("confirmed")
    assert "API_GONE" in codes("cleared") and "API_GONE" not in codes(None)
    assert "API_GONE" not in codes("healed")
    assert {"API_PENDING", "API_GONE"} <= codes("all")
    for bad in ("", "Pending", "bogus"):
        answer = server.client.get("/api/v1/faults", params={"status": bad})
        assert answer.status_code == 400
        assert answer.json()["message"] == "Invalid status parameter value"
        assert answer.json()["parameters"]["value"] == bad


def test_delete_one_and_by_group(server: Server) -> None:
    report(server, "API_DEL_1")
    report(server, "API_DEL_2")
    missing = server.client.delete("/api/v1/faults/API_NEVER")
    assert missing.status_code == 404
    assert missing.json()["message"] == "Fault not found: API_NEVER"
    bulk = server.client.delete("/api/v1/faults", params={"status": "confirmed",
                                                          "reason": "end of shift"})
    assert bulk.status_code == 204 and bulk.headers["X-Medkit-Local-Only"] == "true"
    assert server.client.get("/api/v1/faults", params={"status": "confirmed"}
                             ).json()["items"] == []
    history = server.client.get("/api/v1/history", params={"code": "API_DEL_1",
                                                           "kind": "fault_cleared"}).json()
    assert history["items"][0]["payload"]["actor"] == "anonymous"
    assert history["items"][0]["payload"]["reason"] == "end of shift"


def test_errors_are_json_never_html(server: Server) -> None:
    unknown = server.client.get("/no/such/page")
    assert unknown.status_code == 404 and unknown.json()["reason"] == "not_found"
    wrong = server.client.put("/api/v1/faults")
    assert wrong.status_code == 400 and wrong.json()["reason"] == "invalid"
    bad_code = server.client.get("/api/v1/faults/" + "X" * 300)
    assert bad_code.status_code == 400 and bad_code.json()["reason"] == "invalid"
    bad_time = server.client.get("/api/v1/history", params={"since": "yesterday"})
    assert bad_time.status_code == 400 and "since must be" in bad_time.json()["message"]
    bad_seq = server.client.get("/api/v1/history", params={"from_seq": 5, "to_seq": 2})
    assert bad_seq.status_code == 400 and "the range is empty" in bad_seq.json()["message"]
    bad_limit = server.client.get("/api/v1/history", params={"limit": 0})
    assert bad_limit.status_code == 400 and bad_limit.json()["reason"] == "invalid"
    bad_by = server.client.get("/api/v1/stats", params={"by": "week"})
    assert bad_by.status_code == 400 and "by must be one of" in bad_by.json()["message"]


def test_history_pages_and_exports_match_the_cli(server: Server) -> None:
    for _ in range(3):
        report(server, "API_HIST")
    first = server.client.get("/api/v1/history", params={"limit": 2}).json()
    assert [r["seq"] for r in first["items"]] == [1, 2] and first["next_after_seq"] == 2
    rest = server.client.get("/api/v1/history", params={"after_seq": 2, "limit": 10_000})
    seqs = [r["seq"] for r in rest.json()["items"]]
    assert seqs == list(range(3, 3 + len(seqs))) and rest.json()["next_after_seq"] is None
    for fmt in ("csv", "jsonl"):
        over_http = server.client.get("/api/v1/history", params={"format": fmt}).text
        assert over_http == cli(server.db, "history", "--format", fmt)
    one = server.client.get("/api/v1/history", params={"code": "API_H*", "format": "jsonl"})
    lines = [json.loads(line) for line in one.text.splitlines()]
    assert {r["fault_code"] for r in lines} == {"API_HIST"} and len(lines) == 3
    assert all(len(r["hash"]) == 64 for r in lines)


def test_state_at_and_stats_equal_the_cli(server: Server) -> None:
    report(server, "API_TT")
    seq = report(server, "API_TT", "PASSED")["seq"]
    then = server.client.get("/api/v1/state-at", params={"at": str(seq)}).json()
    assert then["x-medkit"]["seq"] == seq
    assert "API_TT" in {i["fault_code"] for i in then["items"]}
    early = server.client.get("/api/v1/state-at", params={"at": "1"}).json()
    assert early["items"] == []
    params = {"by": "day", "since": "2026-01-01", "until": "2030-01-01T00:00Z",
              "as_of": "2030-01-01T00:00Z"}
    over_http = server.client.get("/api/v1/stats", params=params).json()["items"]
    from_cli = json.loads(cli(server.db, "stats", "--by", "day", "--since", "2026-01-01",
                              "--until", "2030-01-01T00:00Z", "--as-of", "2030-01-01T00:00Z",
                              "--json"))
    assert over_http == from_cli and sum(r["failed_reports"] for r in over_http) > 0
    html = server.client.get("/api/v1/shift-report")
    assert html.status_code == 200 and html.text.startswith("<!DOCTYPE html>")
    assert server.client.get("/api/v1/shift-report", params={"shift": "x"}).status_code == 400


def test_metrics_count_what_this_server_wrote(server: Server) -> None:
    def values() -> dict[tuple[str, tuple[tuple[str, str], ...]], float]:
        text = server.client.get("/metrics").text
        return {(s.name, tuple(sorted(s.labels.items()))): s.value
                for family in text_string_to_metric_families(text) for s in family.samples}

    before = values()
    report(server, "API_METRIC_A")
    report(server, "API_METRIC_A", "PASSED")
    after = values()
    failed = ("faultledger_reports_total", (("event_type", "FAILED"),))
    passed = ("faultledger_reports_total", (("event_type", "PASSED"),))
    assert after[failed] - before.get(failed, 0) == 1
    assert after[passed] - before.get(passed, 0) == 1
    count = ("faultledger_commit_seconds_count", ())
    assert after[count] - before[count] == 2
    listed = server.client.get("/api/v1/faults", params={"status": "all"}).json()["items"]
    confirmed = sum(1 for i in listed if i["status"] == "CONFIRMED"
                    and i["severity_label"] == "CRITICAL")
    assert after[("faultledger_faults", (("severity", "CRITICAL"),
                                         ("status", "CONFIRMED")))] == confirmed
    assert after[("faultledger_last_seq", ())] == server.client.get("/health").json()[
        "last_seq"]


def test_openapi_and_docs(server: Server) -> None:
    spec = server.client.get("/openapi.json").json()
    assert {"/api/v1/faults", "/api/v1/faults/{fault_code}", "/api/v1/faults/stream",
            "/api/v1/reports", "/api/v1/history", "/api/v1/stats", "/metrics"} <= set(
        spec["paths"])
    assert server.client.get("/docs").status_code == 200
