"""Stopping `faultledger http` while a dashboard or another client holds the event stream open:
the stream ends with the closing chunk of its response (not cut off), nothing is logged as an
error, and the process exits 0. The ready line says how many tokens guard the server."""

from __future__ import annotations

import hashlib
import signal
from collections.abc import Callable
from pathlib import Path

import httpx
import pytest

from tests.http.conftest import Server, write_config


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_stopping_with_an_open_stream_is_clean(sig: signal.Signals,
                                               http_server: Callable[..., Server]) -> None:
    server = http_server()
    with httpx.Client(base_url=server.url, timeout=10) as web, web.stream(
            "GET", "/api/v1/faults/stream") as stream:
        assert stream.status_code == 200
        answer = server.client.post("/api/v1/reports", json={
            "fault_code": "STOP_X", "event_type": "FAILED", "severity": 3})
        assert answer.json()["accepted"]
        lines = stream.iter_lines()
        assert next(line for line in lines if line.startswith("event:")) == (
            "event: fault_confirmed")
        server.process.send_signal(sig)
        # The rest of the stream, to its end: a response cut off mid-stream (the old
        # "ASGI callable returned without completing response") raises RemoteProtocolError.
        rest = list(lines)
    assert all(not line.startswith("event:") for line in rest), rest
    assert server.process.wait(timeout=10) == 0
    output = server.output()
    assert "ERROR" not in output and "Traceback" not in output, output
    assert "Cancel" not in output, output  # no task was cut off after the graceful timeout


def test_ready_lines_say_how_many_tokens(tmp_path: Path,
                                         http_server: Callable[..., Server]) -> None:
    open_server = http_server(db=tmp_path / "open.db")
    assert "; no tokens: loopback only; dashboard " in open_server.output()
    tokens = [{"name": name, "role": "viewer",
               "sha256": hashlib.sha256(name.encode()).hexdigest()} for name in ("a", "b")]
    guarded = http_server(db=tmp_path / "guarded.db",
                          config=write_config(tmp_path / "c.yaml", http={"tokens": tokens}))
    assert "; tokens: 2 (a token is needed on every request); dashboard " in guarded.output()
    assert guarded.client.get("/api/v1/faults").status_code == 401  # on loopback too

