"""The alert bench's receiver, in a process of its own (as a real receiver is not in the
fault manager's interpreter): a threaded http.server on 127.0.0.1 that answers every POST
200 and notes when each Idempotency-Key first arrived (time.time()). GET /arrivals answers
them as JSON {key: time}. Prints its port on the first line. Usage: _alert_receiver.py"""

from __future__ import annotations

import json
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

arrivals: dict[str, float] = {}
lock = threading.Lock()


class Handler(BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"
    disable_nagle_algorithm = True

    def do_POST(self) -> None:
        self.rfile.read(int(self.headers.get("Content-Length", "0")))
        at = time.time()
        with lock:
            arrivals.setdefault(self.headers["Idempotency-Key"], at)
        self.send_response(200)
        self.send_header("Content-Length", "0")
        self.end_headers()

    def do_GET(self) -> None:
        with lock:
            body = json.dumps(arrivals).encode()
        self.send_response(200)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *_args: Any) -> None:
        pass


server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
server.daemon_threads = True
print(server.server_address[1], flush=True)
server.serve_forever()
