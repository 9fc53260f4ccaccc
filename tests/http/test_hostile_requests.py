"""Hostile HTTP requests (issue 18) through a real `faultledger http`: each is answered 4xx
with the JSON body of http/errors.py, never a 500 or a traceback in the server's log; a client
that stops reading counts as a dropped stream client."""

from __future__ import annotations

import re
import socket
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from faultledger import FaultLedger, ReportRequest
from tests.http.conftest import Server, start_server, write_config

ODD_EVENT_IDS = [
    "²", "³", "¹", "½", "①", "⑩", "٣", "۳", "१", "１", "𝟙", "Ⅻ", "一", "٫", "∞", "🙂",
    "-1", "+1", "1.0", "1e3", "0x10", "0b1", "0o7", "1_000", "1 2", "1\t2", "1a", "abc",
    "NaN", "inf", "9" * 20, "9223372036854775808", "18446744073709551616", "1" * 100,
]
"""Values no seq is: superscripts and other digits ``str.isdigit`` accepts (``int`` refuses
some, reads others as a number), signs, floats, other bases, beyond 64 bits."""
LATIN_1 = [value for value in ODD_EVENT_IDS if all(ord(c) < 256 for c in value)]
OUTSIDE = "is outside the times the log can hold (1970-01-01T00:00:00Z .. 2262-04-11T23:47:16Z)"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    folder = tmp_path_factory.mktemp("hostile")
    running = start_server(folder / "faults.db", config=write_config(folder / "config.yaml"))
    yield running
    running.stop()


def refused(answer: httpx.Response, status: int, reason: str, words: str) -> None:
    assert answer.status_code == status, answer.text
    assert answer.headers["content-type"].startswith("application/json"), answer.headers
    found = answer.json()
    assert found["reason"] == reason, found
    assert words in found["message"], found


def stream_status(server: Server, **options: object) -> httpx.Response:
    """The answer to a stream request; a stream that opened is closed at once."""
    with server.client.stream("GET", "/api/v1/faults/stream", **options) as answer:  # type: ignore[arg-type]
        if answer.status_code == 200:
            return answer
        answer.read()
        return answer


@pytest.mark.parametrize("value", ODD_EVENT_IDS)
def test_an_odd_last_event_id_is_400_as_header_or_parameter(server: Server, value: str) -> None:
    as_utf8 = stream_status(server, headers={"Last-Event-ID": value.encode()})
    as_parameter = stream_status(server, params={"last_event_id": value})
    for answer in (as_utf8, as_parameter):
        refused(answer, 400, "invalid", "Last-Event-ID must be the seq of an event received")


@pytest.mark.parametrize("value", LATIN_1)
def test_an_odd_last_event_id_in_latin_1_is_400(server: Server, value: str) -> None:
    """HTTP header bytes are read as Latin-1: the byte 0xB2 is the text '²'."""
    answer = stream_status(server, headers={"Last-Event-ID": value.encode("latin-1")})
    refused(answer, 400, "invalid", "Last-Event-ID must be the seq of an event received")


@pytest.mark.parametrize("value", ["0", "007", "9223372036854775807"])
def test_a_seq_as_last_event_id_opens_the_stream(server: Server, value: str) -> None:
    assert stream_status(server, headers={"Last-Event-ID": value}).status_code == 200
    assert stream_status(server, params={"last_event_id": f" {value} "}).status_code == 200


@pytest.mark.parametrize("shift", ["9999-12-31/night", "0001-01-01/night", "9999-12-31/morning",
                                   "2262-04-11/night", "1969-12-31/night"])
@pytest.mark.parametrize("format_", ["html", "json"])
def test_a_shift_outside_the_log_is_400(server: Server, shift: str, format_: str) -> None:
    answer = server.client.get("/api/v1/shift-report", params={"shift": shift,
                                                                "format": format_})
    refused(answer, 400, "invalid", f"shift {shift} {OUTSIDE}")


@pytest.mark.parametrize(("name", "shift"), [("since", "9999-12-31/night"),
                                             ("until", "0001-01-01/night")])
def test_a_stats_bound_outside_the_log_is_400(server: Server, name: str, shift: str) -> None:
    answer = server.client.get("/api/v1/stats", params={name: shift})
    refused(answer, 400, "invalid", f"{name} '{shift}' {OUTSIDE}")


@pytest.mark.parametrize("suffix", ["", ".js", ".css"])
def test_a_5000_character_static_name_is_404(server: Server, suffix: str) -> None:
    answer = server.client.get("/static/" + "a" * 5000 + suffix)
    refused(answer, 404, "not_found", "no such file: 'aaaa")
    assert len(answer.json()["message"]) < 200
    assert server.client.get("/static/dashboard.js").status_code == 200


def test_four_spellings_of_one_event_id_are_one_report(server: Server) -> None:
    event_id = uuid.uuid4()
    canonical = str(event_id)
    spellings = [canonical.upper(), "{" + canonical + "}", f"urn:uuid:{canonical}",
                 event_id.hex]
    answers = [server.client.post("/api/v1/reports", json={
        "fault_code": "SPELLED", "event_type": "FAILED", "severity": 1, "event_id": spelling})
        for spelling in spellings]

    assert [a.status_code for a in answers] == [200] * 4, [a.text for a in answers]
    assert [a.json()["duplicate"] for a in answers] == [False, True, True, True]
    assert {a.json()["event_id"] for a in answers} == {canonical}
    history = server.client.get("/api/v1/history", params={"code": "SPELLED"}).json()["items"]
    assert [r["event_id"] for r in history] == [canonical]


@pytest.mark.parametrize("severity", [4, 255, -1])
def test_a_passed_with_a_severity_off_the_scale_is_refused_like_a_failed(server: Server,
                                                                          severity: int) -> None:
    answers = {kind: server.client.post("/api/v1/reports", json={
        "fault_code": "SEV_SCALE", "event_type": kind, "severity": severity})
        for kind in ("PASSED", "FAILED")}

    for answer in answers.values():
        refused(answer, 400, "invalid",
                f"severity must be 0 (INFO) to 3 (CRITICAL), got {severity}")
    assert answers["PASSED"].json()["message"] == answers["FAILED"].json()["message"]
    assert server.client.get("/api/v1/history", params={"code": "SEV_SCALE"}).json()[
        "items"] == []


def test_the_server_logged_no_traceback_and_no_internal_error(server: Server) -> None:
    """Runs after the tests above (pytest keeps a module's order)."""
    output = server.output()
    assert "Traceback" not in output and "internal error" not in output, output[-3000:]


def dropped(server: Server) -> float:
    found = re.search(r"\nfaultledger_stream_dropped_clients_total (\S+)",
                      server.client.get("/metrics").text)
    assert found is not None
    return float(found.group(1))


def test_a_client_that_stops_reading_counts_as_dropped(tmp_path: Path) -> None:
    """A stream client that reads nothing while events keep coming is ended after its sends
    block for 30 s (by the stream's send timeout, or the server's connection layer before
    it) and counted in faultledger_stream_dropped_clients_total, as one that fell behind the
    buffer is; one warning line, no traceback. Takes about 35 s."""
    db = tmp_path / "f.db"
    server = start_server(db, config=write_config(tmp_path / "c.yaml"))
    try:
        host, port = server.url.removeprefix("http://").rstrip("/").rsplit(":", 1)
        stalled = socket.create_connection((host, int(port)))
        stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        stalled.sendall(f"GET /api/v1/faults/stream HTTP/1.1\r\nHost: {host}:{port}\r\n\r\n"
                        .encode())
        deadline = time.monotonic() + 10
        while server.client.get("/health").json()["stream_clients"] != 1:
            assert time.monotonic() < deadline, server.output()
            time.sleep(0.05)
        with FaultLedger.open(f"sqlite:///{db}") as ledger:
            # 32 MB of events in 8 commits (far more than the socket buffers hold), fewer
            # than the hub's buffer of 10,000: the client blocks sends, never falls behind.
            for batch in range(8):
                ledger.report_many([ReportRequest(f"STALL_{batch}_{i}", "FAILED", 3, "x" * 4000,
                                                  "/stall") for i in range(1000)])
                time.sleep(0.3)
        assert dropped(server) == 0
        deadline = time.monotonic() + 75
        while dropped(server) < 1:
            assert time.monotonic() < deadline, server.output()
            time.sleep(0.5)
        assert server.client.get("/health").json()["stream_clients"] == 0
        stalled.close()
        output = server.output()
        assert "Traceback" not in output, output[-3000:]
        assert re.search(r"event stream of 127\.0\.0\.1:\d+ ended", output), output[-3000:]
    finally:
        server.stop()
