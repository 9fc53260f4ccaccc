"""Connection limits of the HTTP server (docs/http.md, "Limits"): uvicorn's h11 protocol with
the timeouts and the connection cap uvicorn lacks.

uvicorn closes an idle keep-alive connection (``timeout_keep_alive``) and bounds a request's
head (``h11_max_incomplete_event_size``), but waits forever for a request whose head or body
never finishes: a few hundred sockets sending a header line now and then hold as many file
descriptors, and past the open-files limit the server can accept nobody (measured: 0 of 2,400
such connections ever closed; 1,100 made the API unreachable under a 1,024 limit). Its
``limit_concurrency`` does not help: it counts those same sockets, then answers every new
request 503, the honest client's too. So each connection here has

* a **head deadline**: the request line and headers must arrive within ``header_timeout``
  of the request's first byte (of the connection's opening, for its first request);
* a **body deadline**: the body within ``body_timeout`` of the end of the head;
* a **send deadline**: a client that takes nothing of an answer for ``send_timeout`` (the
  transport's buffer stays full) is cut off;

and the server holds at most ``max_connections``. A new connection beyond that closes the
oldest one that is idle (between keep-alive requests), else the oldest still sending its
head, else its body; only when every connection is being answered (an event stream, a long
export) is the new one refused: 503 JSON with ``Retry-After``. An honest client therefore
gets in however many slow sockets are open, and the process never runs out of descriptors.
A request that misses a deadline is answered 408 and closed (a connection that sent nothing
is just closed).
"""

from __future__ import annotations

import asyncio
import json
import logging
import resource
from typing import Any, ClassVar

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

from faultledger.errors import Reason
from faultledger.http.errors import STATUS, body

log = logging.getLogger(__name__)

RESERVED_DESCRIPTORS = 128
"""Open files kept for everything but connections: the database, its WAL, logs, and in
``serve --http`` the ROS node's DDS sockets."""
BACKLOG = 128
"""The listening socket's queue, and how many connections asyncio accepts at once before
any of them is looked at (it uses the one number for both): a flood of waiting connections
takes at most this many descriptors beyond the cap before the oldest are closed. (2048,
uvicorn's default, let one burst exhaust a 1,024 open-files limit: asyncio then stops
accepting anyone for a second.)"""
REFUSING_MOST = 64
"""Connections being refused (waiting for their request to answer it 503) at once; more are
closed at once."""

IDLE, HEAD, BODY, ANSWERING = "idle", "head", "body", "answering"
_EVICTION_ORDER = (IDLE, HEAD, BODY)


def descriptor_cap(wanted: int) -> int:
    """``wanted`` connections, or fewer when the open-files limit would not hold them."""
    soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft == resource.RLIM_INFINITY:
        return wanted
    return max(8, min(wanted, soft - RESERVED_DESCRIPTORS - BACKLOG))


class ConnectionGuard:
    """The connections of one server, oldest first, and the limits they are held to."""

    def __init__(self, max_connections: int, header_timeout: float, body_timeout: float,
                 send_timeout: float) -> None:
        self.max_connections = descriptor_cap(max_connections)
        if self.max_connections < max_connections:
            log.warning("http.max_connections %d lowered to %d: the open-files limit "
                        "(ulimit -n) is %d", max_connections, self.max_connections,
                        resource.getrlimit(resource.RLIMIT_NOFILE)[0])
        self.header_timeout = header_timeout
        self.body_timeout = body_timeout
        self.send_timeout = send_timeout
        self.open: dict[GuardedH11Protocol, None] = {}
        """Admitted connections in the order they opened (a dict keeps it)."""
        self.refusing = 0
        self.counts = {"refused": 0, "evicted": 0, "timed_out": 0, "stalled": 0}

    def admit(self, connection: GuardedH11Protocol) -> bool:
        if len(self.open) >= self.max_connections:
            victim = self._victim()
            if victim is None:
                return False
            self.counts["evicted"] += 1
            self.open.pop(victim, None)  # its socket closes on the loop's next turn
            victim.cut(evicted=True)
        self.open[connection] = None
        return True

    def _victim(self) -> GuardedH11Protocol | None:
        first: dict[str, GuardedH11Protocol] = {}
        for connection in self.open:
            if connection.transport.is_closing():
                continue
            phase = connection.phase
            if phase == IDLE:
                return connection
            if phase in _EVICTION_ORDER:
                first.setdefault(phase, connection)
        return next((first[p] for p in _EVICTION_ORDER if p in first), None)

    def forget(self, connection: GuardedH11Protocol) -> None:
        self.open.pop(connection, None)


def protocol(guard: ConnectionGuard) -> type[GuardedH11Protocol]:
    """The protocol class uvicorn makes each connection with (``Config(http=...)``)."""
    return type("GuardedH11", (GuardedH11Protocol,), {"guard": guard})


class GuardedH11Protocol(H11Protocol):
    guard: ClassVar[ConnectionGuard]

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._deadline: asyncio.TimerHandle | None = None
        self._deadline_phase = ""
        self._stall: asyncio.TimerHandle | None = None
        self._refusing = False

    # -- what the connection is doing -----------------------------------------------------
    @property
    def phase(self) -> str:
        state = self.conn.their_state
        if state is h11.IDLE:
            return IDLE if self.timeout_keep_alive_task is not None else HEAD
        if state is h11.SEND_BODY:
            return BODY
        return ANSWERING

    def _watch(self) -> None:
        """(Re)arm the deadline of the phase the connection is in, once per phase."""
        if self.transport is None or self.transport.is_closing():
            return
        phase = self.phase
        if phase == self._deadline_phase:
            return
        self._cancel_deadline()
        self._deadline_phase = phase
        timeout = {HEAD: self.guard.header_timeout, BODY: self.guard.body_timeout}.get(phase)
        if timeout is not None:
            self._deadline = self.loop.call_later(timeout, self._expire, phase)

    def _cancel_deadline(self) -> None:
        if self._deadline is not None:
            self._deadline.cancel()
            self._deadline = None

    def _expire(self, phase: str) -> None:
        self._deadline = None
        if self.phase != phase or self.transport.is_closing():
            return
        self.guard.counts["timed_out"] += 1
        self.cut(evicted=False)

    def cut(self, *, evicted: bool) -> None:
        """Close the connection: idle, quietly; in the middle of a request, with a 408 (a
        deadline missed) or 503 (closed to make room) the client may still read."""
        phase = self.phase
        started = self.cycle is not None and self.cycle.response_started
        received = phase == BODY or bool(self.conn.trailing_data[0])
        if phase in (HEAD, BODY) and received and not started:
            what = ("request head" if phase == HEAD else "request body")
            if evicted:
                self._write_raw(Reason.UNAVAILABLE, 503, "Service Unavailable",
                                f"closed to make room for a new connection: the server holds "
                                f"at most {self.guard.max_connections} (http.max_connections) "
                                f"and this {what} was still incomplete")
            else:
                limit = (f"{self.guard.header_timeout:g} s (http.header_timeout_sec)"
                         if phase == HEAD else
                         f"{self.guard.body_timeout:g} s (http.body_timeout_sec)")
                self._write_raw(Reason.INVALID, 408, "Request Timeout",
                                f"the {what} did not arrive within {limit}")
        if self.cycle is not None and not self.cycle.response_complete:
            self.cycle.disconnected = True
            self.cycle.message_event.set()
        self.transport.close()

    def _write_raw(self, reason: Reason, status: int, phrase: str, message: str) -> None:
        """A whole answer written straight to the socket: h11 cannot answer a request whose
        head it has not seen."""
        payload = json.dumps(body(reason, message)).encode()
        extra = b"retry-after: 1\r\n" if status == 503 else b""
        self.transport.write(b"HTTP/1.1 %d %s\r\ncontent-type: application/json\r\n"
                             b"content-length: %d\r\n%sconnection: close\r\n\r\n%s"
                             % (status, phrase.encode(), len(payload), extra, payload))

    # -- uvicorn's protocol, watched --------------------------------------------------------
    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        if not self.guard.admit(self):
            if self.guard.refusing >= REFUSING_MOST:
                self.guard.counts["refused"] += 1
                self.transport.abort()
                return
            # Answered 503 once its request is read (a response before it would be lost to
            # the reset of closing a socket with unread data); held to the head deadline.
            self._refusing = True
            self.guard.refusing += 1
            self.app = _busy(self.guard)
        self._watch()

    def connection_lost(self, exc: Exception | None) -> None:
        self._cancel_deadline()
        self._cancel_stall()
        if self._refusing:
            self._refusing = False
            self.guard.refusing -= 1
        self.guard.forget(self)
        super().connection_lost(exc)

    def data_received(self, data: bytes) -> None:
        super().data_received(data)
        self._watch()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        self._watch()

    def pause_writing(self) -> None:
        super().pause_writing()
        if self._stall is None:
            self._stall = self.loop.call_later(self.guard.send_timeout, self._stalled)

    def resume_writing(self) -> None:
        super().resume_writing()
        self._cancel_stall()

    def _cancel_stall(self) -> None:
        if self._stall is not None:
            self._stall.cancel()
            self._stall = None

    def _stalled(self) -> None:
        self._stall = None
        self.guard.counts["stalled"] += 1
        log.info("closed a connection from %s: it read nothing of its answer for %g s "
                 "(http.send_timeout_sec)", _peer(self.client), self.guard.send_timeout)
        self.transport.abort()

    def send_400_response(self, msg: str) -> None:
        """A request h11 cannot parse, or whose head is over http.max_header_bytes: JSON like
        every other refusal, instead of uvicorn's plain text."""
        payload = json.dumps(body(Reason.INVALID, (
            "malformed HTTP request, or its line and headers are longer than "
            "http.max_header_bytes"))).encode()
        try:
            self.transport.write(self.conn.send(h11.Response(
                status_code=400, reason=b"Bad Request",
                headers=[(b"content-type", b"application/json"),
                         (b"content-length", str(len(payload)).encode()),
                         (b"connection", b"close")])) or b"")
            self.transport.write(self.conn.send(h11.Data(data=payload)) or b"")
            self.transport.write(self.conn.send(h11.EndOfMessage()) or b"")
        except h11.LocalProtocolError:
            pass  # the response had started: nothing more can be said
        self.transport.close()


def _busy(guard: ConnectionGuard) -> Any:
    async def app(scope: Any, receive: Any, send: Any) -> None:
        guard.counts["refused"] += 1
        payload = json.dumps(body(Reason.UNAVAILABLE, (
            f"busy: all {guard.max_connections} connections (http.max_connections) are "
            "being answered; retry in a second"))).encode()
        await send({"type": "http.response.start", "status": STATUS[Reason.UNAVAILABLE],
                    "headers": [(b"content-type", b"application/json"),
                                (b"content-length", str(len(payload)).encode()),
                                (b"retry-after", b"1"), (b"connection", b"close")]})
        await send({"type": "http.response.body", "body": payload})
    return app


def _peer(client: tuple[str, int] | None) -> str:
    return f"{client[0]}:{client[1]}" if client else "?"
