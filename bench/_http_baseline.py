"""The bench's baseline server: a bare FastAPI route returning precomputed bytes, on uvicorn
with the same settings as faultledger's HTTP server. Usage: _http_baseline.py FILE"""

from __future__ import annotations

import socket
import sys
from pathlib import Path

import uvicorn
from fastapi import FastAPI, Response

content = Path(sys.argv[1]).read_bytes()
app = FastAPI()


@app.get("/api/v1/faults")
def faults() -> Response:
    return Response(content, media_type="application/json")


sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM, socket.IPPROTO_TCP)  # as ours
sock.bind(("127.0.0.1", 0))
sock.listen(2048)
print(f"baseline ready: http://127.0.0.1:{sock.getsockname()[1]}/", flush=True)
uvicorn.Server(uvicorn.Config(app, log_level="warning", access_log=False)).run(sockets=[sock])
