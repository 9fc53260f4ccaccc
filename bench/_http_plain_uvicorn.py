"""The bench's baseline for connection limits: faultledger's own app on uvicorn with
uvicorn's defaults (h11, backlog 2048, no head or body deadline, no connection cap), as
`faultledger http` ran before issue 18. Usage: _http_plain_uvicorn.py DB"""

from __future__ import annotations

import socket
import sys

import uvicorn

from faultledger import FaultLedger
from faultledger.http.app import create_app
from faultledger.http.protection import AllowedHosts
from faultledger.service.config import HttpSettings
from faultledger.service.tokens import TokenBook

ledger = FaultLedger.open(f"sqlite:///{sys.argv[1]}")
sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM, socket.IPPROTO_TCP)
sock.bind(("127.0.0.1", 0))
sock.listen(2048)
port = sock.getsockname()[1]
app = create_app(ledger, HttpSettings(tokens_file=None), ledger.calendar, TokenBook([]),
                 hosts=AllowedHosts("127.0.0.1", port))
print(f"baseline ready: http://127.0.0.1:{port}/", flush=True)
uvicorn.Server(uvicorn.Config(app, log_level="critical", access_log=False)).run(sockets=[sock])
