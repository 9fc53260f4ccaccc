"""A read-only server (beside a fault manager that writes) refuses changes with 503; CORS is
closed unless origins are configured."""

from __future__ import annotations

from pathlib import Path

from faultledger import FaultLedger
from tests.http.conftest import start_server, write_config


def test_a_read_only_server_answers_reads_and_refuses_writes(tmp_path: Path) -> None:
    db = tmp_path / "f.db"
    with FaultLedger.open(f"sqlite:///{db}") as ledger:
        ledger.report("RO_FAULT", "FAILED", 3, "", "/x")
    server = start_server(db, "--read-only")
    try:
        assert [i["fault_code"] for i in server.client.get("/api/v1/faults").json()["items"]
                ] == ["RO_FAULT"]
        cleared = server.client.delete("/api/v1/faults/RO_FAULT")
        assert cleared.status_code == 503 and cleared.json()["reason"] == "unavailable"
        posted = server.client.post("/api/v1/reports", json={"fault_code": "RO_NEW",
                                                              "event_type": "FAILED"})
        assert posted.status_code == 503 and posted.json()["reason"] == "unavailable"
        assert server.client.get("/health").json()["read_only"] is True
    finally:
        server.stop()


def test_cors_is_closed_unless_configured(tmp_path: Path) -> None:
    preflight = {"Origin": "http://ops.example", "Access-Control-Request-Method": "GET"}
    closed = start_server(tmp_path / "a.db")
    try:
        answer = closed.client.get("/api/v1/faults", headers={"Origin": "http://ops.example"})
        assert "access-control-allow-origin" not in answer.headers
        assert "access-control-allow-origin" not in closed.client.options(
            "/api/v1/faults", headers=preflight).headers
    finally:
        closed.stop()
    config = write_config(tmp_path / "c.yaml", http={"cors_origins": ["http://ops.example"]})
    opened = start_server(tmp_path / "b.db", config=config)
    try:
        answer = opened.client.options("/api/v1/faults", headers=preflight)
        assert answer.headers["access-control-allow-origin"] == "http://ops.example"
        other = opened.client.options("/api/v1/faults", headers={
            **preflight, "Origin": "http://elsewhere.example"})
        assert "access-control-allow-origin" not in other.headers
    finally:
        opened.stop()
