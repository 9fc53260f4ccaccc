"""Bearer tokens per role, the loopback rule, and the event stream: live, resumed after a
dropped connection and after a server restart (no gap, no duplicate), and a stalled client."""

from __future__ import annotations

import re
import socket
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx

from faultledger import FaultLedger, ReportRequest
from tests.http.conftest import start_server, write_config

EVENT = re.compile(r"id: (\d+)\nevent: (\w+)\ndata: (.*)\n")


def token(file: Path, name: str, role: str) -> str:
    done = subprocess.run([sys.executable, "-m", "faultledger.cli.main", "token", "create",
                           "--name", name, "--role", role, "--file", str(file)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def bearer(value: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {value}"}


def test_roles_decide_what_a_token_may_do(tmp_path: Path) -> None:
    tokens = tmp_path / "tokens.yaml"
    viewer, reporter = token(tokens, "wall-display", "viewer"), token(tokens, "plc", "reporter")
    operator, admin = token(tokens, "alice", "operator"), token(tokens, "root", "admin")
    assert stat.S_IMODE(tokens.stat().st_mode) == 0o600
    stored = tokens.read_text()
    assert all(t not in stored for t in (viewer, reporter, operator, admin))
    again = subprocess.run([sys.executable, "-m", "faultledger.cli.main", "token", "create",
                            "--name", "alice", "--role", "viewer", "--file", str(tokens)],
                           capture_output=True, text=True, timeout=60)
    assert again.returncode == 2 and "a token named 'alice' exists" in again.stderr
    config = write_config(tmp_path / "c.yaml", http={"tokens_file": str(tokens)})
    server = start_server(tmp_path / "f.db", config=config)
    try:
        client = server.client
        body = {"fault_code": "AUTH_X", "event_type": "FAILED", "severity": 3}
        none = client.get("/api/v1/faults")
        assert none.status_code == 401 and none.json()["reason"] == "unauthorized"
        assert none.headers["WWW-Authenticate"].startswith("Bearer")
        assert client.get("/api/v1/faults", headers=bearer("flt_wrong")).status_code == 401
        assert client.get("/api/v1/faults", headers={"Authorization": viewer}).status_code == 401
        assert client.get("/health").status_code == 200
        assert client.get("/api/v1/faults", headers=bearer(viewer)).status_code == 200
        refused = client.post("/api/v1/reports", json=body, headers=bearer(viewer))
        assert refused.status_code == 403 and refused.json()["reason"] == "forbidden"
        assert "needs reporter or operator or admin" in refused.json()["message"]
        assert client.post("/api/v1/reports", json=body, headers=bearer(reporter)).json()[
            "accepted"]
        assert client.get("/api/v1/faults", headers=bearer(reporter)).status_code == 403
        assert client.delete("/api/v1/faults/AUTH_X", headers=bearer(viewer)).status_code == 403
        assert client.delete("/api/v1/faults/AUTH_X", headers=bearer(operator)
                             ).status_code == 204
        assert client.get("/metrics", headers=bearer(admin)).status_code == 200
        history = client.get("/api/v1/history", params={"code": "AUTH_X"},
                             headers=bearer(admin)).json()["items"]
        assert history[0]["source_id"] == "http:plc"
        assert history[-1]["payload"]["actor"] == "alice"
    finally:
        server.stop()


def test_no_tokens_means_loopback_only(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "-m", "faultledger.cli.main", "http", "--db",
                           str(tmp_path / "f.db"), "--listen", "0.0.0.0:0"],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert "refusing to listen on 0.0.0.0 without tokens" in done.stderr


class Reader:
    """One stream client on its own thread, collecting (id, event, data) blocks."""

    def __init__(self, url: str, last_event_id: int | None = None) -> None:
        self.events: list[tuple[int, str]] = []
        self._stop = threading.Event()
        headers = {} if last_event_id is None else {"Last-Event-ID": str(last_event_id)}
        self._client = httpx.Client(base_url=url, timeout=httpx.Timeout(5, read=None))
        self._response = self._client.send(
            self._client.build_request("GET", "/api/v1/faults/stream", headers=headers),
            stream=True)
        assert self._response.status_code == 200
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        text = ""
        try:
            for chunk in self._response.iter_text():
                text += chunk
                while "\n\n" in text:
                    block, text = text.split("\n\n", 1)
                    found = EVENT.match(block + "\n")
                    if found:
                        self.events.append((int(found.group(1)), found.group(2)))
        except (httpx.HTTPError, RuntimeError):
            pass

    def wait_for(self, count: int, timeout: float = 10.0) -> None:
        deadline = time.monotonic() + timeout
        while len(self.events) < count and time.monotonic() < deadline:
            time.sleep(0.02)
        assert len(self.events) >= count, f"{len(self.events)} of {count} events"

    def close(self) -> None:
        self._response.close()
        self._client.close()


def write(db: Path, codes: list[str]) -> None:
    """Records from another process (this test's own ledger on the same file)."""
    with FaultLedger.open(f"sqlite:///{db}") as ledger:
        for code in codes:
            ledger.report(code, "FAILED", 3, "", "/stream")


def test_stream_is_live_and_resumes_without_gap_or_duplicate(tmp_path: Path) -> None:
    db = tmp_path / "f.db"
    server = start_server(db)
    try:
        write(db, ["OLD"])  # before anyone listens: a stream from now never sends it
        time.sleep(1.5)
        steady = Reader(server.url)
        away = Reader(server.url)
        write(db, ["S1", "S1", "S2"])
        away.wait_for(3)
        assert [e for _, e in away.events] == ["fault_confirmed", "fault_updated",
                                               "fault_confirmed"]
        last = away.events[-1][0]
        away.close()
        write(db, ["S3", "S1"])
        steady.wait_for(5)
        back = Reader(server.url, last_event_id=last)
        write(db, ["S4"])
        back.wait_for(3)
        steady.wait_for(6)
        assert back.events == steady.events[3:]
        assert [i for i, _ in steady.events] == sorted({i for i, _ in steady.events})
        ids_before_restart = steady.events
        steady.close()
        back.close()
    finally:
        server.stop()
    write(db, ["R1", "R2"])  # while no server runs
    restarted = start_server(db)
    try:
        resumed = Reader(restarted.url, last_event_id=ids_before_restart[-1][0])
        write(db, ["R3"])
        resumed.wait_for(3)
        time.sleep(0.3)
        assert len(resumed.events) == 3
        assert resumed.events[0][0] > ids_before_restart[-1][0]
        assert [e for _, e in resumed.events] == ["fault_confirmed"] * 3
        bad = restarted.client.get("/api/v1/faults/stream", headers={"Last-Event-ID": "abc"})
        assert bad.status_code == 400 and bad.json()["reason"] == "invalid"
        resumed.close()
    finally:
        restarted.stop()


def flood(db: Path, count: int, batch: int) -> float:
    """``count`` CRITICAL reports (each one announced) in batches; the seconds it took."""
    started = time.monotonic()
    with FaultLedger.open(f"sqlite:///{db}") as ledger:
        for first in range(0, count, batch):
            ledger.report_many([ReportRequest(f"FLOOD_{i}", "FAILED", 3, "x" * 200, "/flood")
                                for i in range(first, min(count, first + batch))])
    return time.monotonic() - started


def test_a_stalled_client_never_slows_the_writer_or_the_others(tmp_path: Path) -> None:
    db = tmp_path / "f.db"
    server = start_server(db)
    try:
        host, port = server.url.removeprefix("http://").rstrip("/").rsplit(":", 1)
        stalled = socket.create_connection((host, int(port)))
        stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        stalled.sendall(f"GET /api/v1/faults/stream HTTP/1.1\r\nHost: {host}:{port}\r\n"
                        "\r\n".encode())
        normal = Reader(server.url)
        time.sleep(0.5)
        flood(db, 3000, 100)
        normal.wait_for(3000, timeout=30)
        assert [i for i, _ in normal.events] == sorted({i for i, _ in normal.events})
        assert server.client.get("/health").json()["stream_clients"] == 2
        stalled.close()
        normal.close()
    finally:
        server.stop()


def test_a_client_further_behind_than_the_buffer_is_dropped_and_resumes(tmp_path: Path
                                                                         ) -> None:
    db = tmp_path / "f.db"
    server = start_server(db, config=write_config(tmp_path / "c.yaml",
                                                  http={"stream_buffer": 100}))
    try:
        before = server.client.get("/health").json()["last_seq"]
        behind = Reader(server.url)
        time.sleep(0.3)
        flood(db, 500, 500)  # one commit: caught up at once, 5 x the buffer
        deadline = time.monotonic() + 10
        while "faultledger_stream_dropped_clients_total 1.0" not in server.client.get(
                "/metrics").text:
            assert time.monotonic() < deadline
            time.sleep(0.1)
        behind._thread.join(5)
        assert not behind._thread.is_alive()  # the server ended that stream
        last = behind.events[-1][0] if behind.events else before
        resumed = Reader(server.url, last_event_id=last)
        resumed.wait_for(500 - len(behind.events))
        got = [i for i, _ in behind.events + resumed.events]
        assert len(got) == 500 and got == sorted(set(got))
        behind.close()
        resumed.close()
    finally:
        server.stop()
