"""The operator's day over HTTP with a real server (issue 21): acknowledge and shelve with the
operator role and the token's name as actor, refusals that store nothing, the list's shelved
views, the detail's episodes, the stream's new events, and a shelving that expires while the
server is killed -9."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx

from tests.http.conftest import start_server, write_config

CLI = [sys.executable, "-m", "faultledger.cli.main"]


def token(file: Path, name: str, role: str) -> str:
    done = subprocess.run([*CLI, "token", "create", "--name", name, "--role", role, "--file",
                           str(file)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def bearer(value: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {value}"}


def report(client: httpx.Client, code: str, kind: str = "FAILED", **headers: str) -> None:
    answer = client.post("/api/v1/reports", json={"fault_code": code, "event_type": kind,
                                                  "severity": 2, "source_id": "/robot/arm"},
                         headers=headers)
    assert answer.json()["accepted"], answer.text


def records(client: httpx.Client, headers: dict[str, str]) -> int:
    return len(client.get("/api/v1/history", params={"limit": 1000},
                          headers=headers).json()["items"])


def test_acknowledge_needs_the_operator_role_and_records_the_token_name(tmp_path: Path
                                                                        ) -> None:
    tokens = tmp_path / "tokens.yaml"
    viewer, alice = token(tokens, "wall", "viewer"), token(tokens, "alice", "operator")
    bob = token(tokens, "bob", "operator")
    config = write_config(tmp_path / "c.yaml", http={"tokens_file": str(tokens)})
    server = start_server(tmp_path / "f.db", config=config)
    try:
        client = server.client
        report(client, "ARM_OVERHEAT", **bearer(alice))
        refused = client.post("/api/v1/faults/ARM_OVERHEAT/ack", headers=bearer(viewer))
        assert refused.status_code == 403, refused.text
        before = records(client, bearer(alice))
        done = client.post("/api/v1/faults/ARM_OVERHEAT/ack", json={"note": "cooling down"},
                           headers=bearer(alice))
        assert done.status_code == 200, done.text
        assert done.json()["recorded"] is True
        assert done.json()["fault"]["acknowledged"]["by"] == "alice"
        assert done.json()["fault"]["status"] == "CONFIRMED"  # the status stays
        again = client.post("/api/v1/faults/ARM_OVERHEAT/ack", headers=bearer(bob)).json()
        assert again["recorded"] is False and "already acknowledged by alice" in again["message"]
        assert records(client, bearer(alice)) == before + 1
        detail = client.get("/api/v1/faults/ARM_OVERHEAT", headers=bearer(viewer)).json()
        assert detail["x-medkit"]["acknowledged"]["note"] == "cooling down"
        # Refusals store nothing: unknown fault, bad note, a CLEARED fault.
        assert client.post("/api/v1/faults/NOPE/ack", headers=bearer(alice)).status_code == 404
        bad = client.post("/api/v1/faults/ARM_OVERHEAT/ack", json={"note": "a\x00b"},
                          headers=bearer(alice))
        assert bad.status_code == 400 and "NUL" in bad.json()["message"]
        assert client.delete("/api/v1/faults/ARM_OVERHEAT", headers=bearer(alice)
                             ).status_code == 204
        cleared = client.post("/api/v1/faults/ARM_OVERHEAT/ack", headers=bearer(alice))
        assert cleared.status_code == 409 and "CLEARED" in cleared.json()["message"]
        assert records(client, bearer(alice)) == before + 2  # ack + clear, nothing else
        # A new episode needs a new acknowledgement; the first occurrence ever stays.
        report(client, "ARM_OVERHEAT", **bearer(alice))
        detail = client.get("/api/v1/faults/ARM_OVERHEAT", headers=bearer(viewer)).json()
        extra = detail["x-medkit"]
        assert "acknowledged" not in extra and extra["episode"] == 2
        assert extra["first_occurred_ever"] < extra["episode_started"]
        assert (extra["occurrences_in_episode"], extra["occurrences_total"]) == (1, 2)
        history = client.get("/api/v1/history", params={"code": "ARM_OVERHEAT"},
                             headers=bearer(alice)).json()["items"]
        acks = [item for item in history if item["kind"] == "fault_acknowledged"]
        assert [(a["payload"]["actor"], a["payload"]["episode"]) for a in acks] == [("alice", 1)]
    finally:
        server.stop()


def test_shelved_faults_leave_the_operators_list_until_unshelved(tmp_path: Path) -> None:
    config = write_config(tmp_path / "c.yaml")
    server = start_server(tmp_path / "f.db", config=config)
    try:
        client = server.client
        for code in ("LIDAR_FLICKER", "MOTOR_STALL"):
            report(client, code)
        answer = client.post("/api/v1/faults/LIDAR_FLICKER/shelve",
                             json={"for": "2h", "reason": "known flicker"})
        assert answer.status_code == 200, answer.text
        shelf = answer.json()["fault"]["shelved"]
        assert 7199 < shelf["until"] - shelf["at"] < 7201 and shelf["reason"] == "known flicker"

        def codes(view: str | None) -> list[str]:
            params = {} if view is None else {"shelved": view}
            items = client.get("/api/v1/faults", params=params).json()["items"]
            return [item["fault_code"] for item in items]

        assert codes(None) == ["LIDAR_FLICKER", "MOTOR_STALL"]  # medkit's list: every fault
        assert codes("hide") == ["MOTOR_STALL"]
        assert codes("only") == ["LIDAR_FLICKER"]
        bad = client.get("/api/v1/faults", params={"shelved": "maybe"})
        assert bad.status_code == 400 and bad.json()["parameters"]["parameter"] == "shelved"
        for body in ({"for": "0m"}, {"for": "31d"}, {"for": "soon"}, {"reason": "no for"}):
            refused = client.post("/api/v1/faults/MOTOR_STALL/shelve", json=body)
            assert refused.status_code in (400, 422), (body, refused.text)
        assert codes("only") == ["LIDAR_FLICKER"]  # none of them shelved anything
        assert client.post("/api/v1/faults/LIDAR_FLICKER/unshelve").status_code == 200
        assert codes("hide") == ["LIDAR_FLICKER", "MOTOR_STALL"]
        twice = client.post("/api/v1/faults/LIDAR_FLICKER/unshelve")
        assert twice.status_code == 409 and "not shelved" in twice.json()["message"]
    finally:
        server.stop()


def test_the_stream_announces_acknowledgements_and_shelvings(tmp_path: Path) -> None:
    server = start_server(tmp_path / "f.db", config=write_config(tmp_path / "c.yaml"))
    try:
        report(server.client, "DOCK_MISSED")
        seen: list[str] = []
        with httpx.Client(base_url=server.url, timeout=10) as reader, reader.stream(
                "GET", "/api/v1/faults/stream", headers={"Last-Event-ID": "0"}) as stream:
            server.client.post("/api/v1/faults/DOCK_MISSED/ack", json={"note": "on my way"})
            server.client.post("/api/v1/faults/DOCK_MISSED/shelve", json={"for": "1h"})
            for line in stream.iter_lines():
                if line.startswith("event: "):
                    seen.append(line.removeprefix("event: "))
                if len(seen) == 3:
                    break
        assert seen == ["fault_confirmed", "fault_acknowledged", "fault_shelved"]
    finally:
        server.stop()


def test_a_shelving_expires_as_a_record_after_a_kill_9(tmp_path: Path) -> None:
    """The serving process writes the end of an expired shelving, stamped with the expiry
    time; one killed -9 before it writes it on its next start, and a rebuild agrees."""
    db = tmp_path / "f.db"
    config = write_config(tmp_path / "c.yaml")
    server = start_server(db, config=config)
    report(server.client, "GRIPPER_SLIP")
    shelved = server.client.post("/api/v1/faults/GRIPPER_SLIP/shelve",
                                 json={"for": "2s", "reason": "recalibrating"}).json()
    until = shelved["fault"]["shelved"]["until"]
    server.process.send_signal(signal.SIGKILL)
    server.process.wait()
    server.client.close()
    time.sleep(max(0.0, until - time.time()) + 0.5)
    server = start_server(db, config=config)
    try:
        deadline = time.monotonic() + 10
        while True:
            fault = server.client.get("/api/v1/faults/GRIPPER_SLIP").json()["x-medkit"]
            if "shelved" not in fault or time.monotonic() > deadline:
                break
            time.sleep(0.1)
        assert "shelved" not in fault
        history = server.client.get("/api/v1/history", params={"code": "GRIPPER_SLIP"}).json()
        ends = [item for item in history["items"] if item["kind"] == "fault_unshelved"]
        assert len(ends) == 1 and ends[0]["payload"]["actor"] == "timer"
        stamped = ends[0]["occurred_at"]
        assert abs(_epoch(stamped) - until) < 0.001  # the expiry time, not the restart's
    finally:
        server.stop()
    rebuilt = subprocess.run([*CLI, "rebuild", "--db", str(db)], capture_output=True,
                             text=True, timeout=60)
    assert rebuilt.returncode == 0, rebuilt.stderr
    shown = subprocess.run([*CLI, "show", "GRIPPER_SLIP", "--json", "--db", str(db)],
                           capture_output=True, text=True, timeout=60)
    assert json.loads(shown.stdout)["shelved"] is None


def _epoch(text: str) -> float:
    from datetime import datetime
    return datetime.fromisoformat(text.replace("Z", "+00:00")).timestamp()
