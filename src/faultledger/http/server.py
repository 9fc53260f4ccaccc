"""Running the HTTP adapter: `faultledger http` (alone) and `faultledger serve --http` (beside
the ROS node, over the same ledger: one writer per process).

Binds 127.0.0.1 unless told otherwise; any other address needs tokens (docs/http.md, "Auth").
"""

from __future__ import annotations

import ipaddress
import logging
import signal
import socket
import sys
import threading
import time

import uvicorn

from faultledger.domain.shifts import ShiftCalendar
from faultledger.errors import ConfigError
from faultledger.http.app import create_app
from faultledger.http.connections import BACKLOG, ConnectionGuard, protocol
from faultledger.http.context import Context
from faultledger.http.protection import AllowedHosts
from faultledger.service.config import HttpSettings
from faultledger.service.ledger import FaultLedger
from faultledger.service.tokens import TokenBook, configured
from faultledger.startup_heap import freeze_startup_heap

log = logging.getLogger(__name__)
START_TIMEOUT_SEC = 10.0
SWITCH_INTERVAL_SEC = 0.001


def parse_listen(text: str) -> tuple[str, int]:
    """``[HOST:]PORT`` (``8080``, ``127.0.0.1:8080``, ``[::1]:8080``, ``0.0.0.0:80``)."""
    value = text.strip()
    host, _, port_text = value.rpartition(":")
    host = host.strip("[]") or "127.0.0.1"
    if not port_text.isdigit() or not 0 <= int(port_text) <= 65535:
        raise ConfigError(f"listen address must be [HOST:]PORT with a port 0..65535 "
                          f"(e.g. 8080 or 127.0.0.1:8080), got {value!r}")
    return host, int(port_text)


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_exposure(host: str, tokens: TokenBook) -> None:
    """Bound to anything but loopback, the server refuses to start without tokens."""
    if not is_loopback(host) and not tokens:
        raise ConfigError(
            f"refusing to listen on {host} without tokens: anyone on that network could "
            "read and clear faults. Create one (faultledger token create --name NAME --role "
            "ROLE) or listen on 127.0.0.1")


class HttpServer:
    """uvicorn over an open ledger, in the foreground (``run``) or a thread (``start``)."""

    def __init__(self, ledger: FaultLedger, settings: HttpSettings, calendar: ShiftCalendar,
                 listen: str | None = None, *, read_only: bool = False,
                 fleet_labels: dict[str, dict[str, str]] | None = None) -> None:
        self.host, self.port = parse_listen(listen or settings.listen)
        tokens = TokenBook(configured(settings))
        check_exposure(self.host, tokens)
        self.tokens = tokens
        self._socket = _bind(self.host, self.port)
        self.port = self._socket.getsockname()[1]
        try:
            hosts = AllowedHosts(self.host, self.port, settings.allowed_hosts)
            self.app = create_app(ledger, settings, calendar, tokens, hosts=hosts,
                                  read_only=read_only, loopback=is_loopback(self.host),
                                  fleet_labels=fleet_labels)
        except BaseException:
            self._socket.close()
            raise
        # uvicorn's h11 protocol with the deadlines and the connection cap it lacks
        # (connections.py); its own keep-alive timeout and head size limit.
        self.connections = ConnectionGuard(settings.max_connections,
                                           settings.header_timeout_sec,
                                           settings.body_timeout_sec, settings.send_timeout_sec)
        config = uvicorn.Config(self.app, log_level="warning", access_log=False,
                                timeout_graceful_shutdown=2, lifespan="on",
                                http=protocol(self.connections),
                                timeout_keep_alive=settings.keep_alive_sec,
                                backlog=BACKLOG,
                                h11_max_incomplete_event_size=settings.max_header_bytes)
        self.server = uvicorn.Server(config)
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"

    @property
    def access(self) -> str:
        """What the ready lines say of tokens (docs/http.md, "Auth")."""
        if not self.tokens:
            return "no tokens: loopback only"
        return f"tokens: {len(self.tokens)} (a token is needed on every request)"

    def run(self) -> None:
        """Serve until SIGINT or SIGTERM (the main thread waits for them itself), then stop as
        ``stop`` does: open streams end cleanly, and the caller returns normally (exit 0).
        uvicorn's own handlers would cut streams off and raise the signal again afterwards."""
        stopping = threading.Event()
        previous = {number: signal.signal(number, lambda *_: stopping.set())
                    for number in (signal.SIGINT, signal.SIGTERM)}
        try:
            self.start()
            assert self._thread is not None
            while not stopping.wait(0.5) and self._thread.is_alive():
                pass
        finally:
            self.stop()
            for number, handler in previous.items():
                signal.signal(number, handler)

    def start(self) -> None:
        """Serve in a background thread; returns once it accepts connections."""
        # With the start-up heap frozen, a heavy read's full collection stops every thread
        # for ~25 ms instead of ~120.
        freeze_startup_heap()
        # Threads take turns holding the GIL every switch interval: 1 ms instead of Python's
        # 5 lets the event loop (and a ROS executor) in sooner while a heavy read computes.
        sys.setswitchinterval(min(sys.getswitchinterval(), SWITCH_INTERVAL_SEC))
        self._thread = threading.Thread(target=self.server.run,
                                        kwargs={"sockets": [self._socket]},
                                        name="faultledger-http", daemon=True)
        self._thread.start()
        deadline = time.monotonic() + START_TIMEOUT_SEC
        while not self.server.started:
            if not self._thread.is_alive() or time.monotonic() > deadline:
                raise ConfigError(f"the HTTP server on {self.url} did not start")
            time.sleep(0.02)

    def stop(self) -> None:
        """Stop serving: every event stream ends first, with the closing chunk of its response
        (uvicorn would otherwise wait for those endless responses, then cancel them)."""
        context: Context = self.app.state.context
        context.hub.close()
        self.server.should_exit = True
        if self._thread is not None:
            self._thread.join(timeout=5)
        self._socket.close()


def _bind(host: str, port: int) -> socket.socket:
    """The listening socket, bound before uvicorn starts so a taken port is a clear error."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    # IPPROTO_TCP, not 0: asyncio sets TCP_NODELAY only on sockets that say they are TCP;
    # without it every keep-alive answer waits ~40 ms (Nagle against delayed ACKs).
    sock = socket.socket(family, socket.SOCK_STREAM, socket.IPPROTO_TCP)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as error:
        sock.close()
        raise ConfigError(f"cannot listen on {host}:{port}: {error.strerror or error}") from None
    sock.listen(BACKLOG)
    sock.set_inheritable(True)
    return sock
