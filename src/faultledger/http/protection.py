"""What a browser may make this server do (docs/http.md, "Browsers: hosts, origins, framing").

* **Host.** Only the host names the server is meant to be reached by are answered: the listen
  address, ``localhost``, ``127.0.0.1`` and ``[::1]`` with the server's port, plus
  ``http.allowed_hosts``. A page from another name that resolves to this machine (DNS
  rebinding: ``evil.test`` → 127.0.0.1) sends ``Host: evil.test:PORT`` and is refused 400,
  so it can neither read nor change anything, with or without tokens. A server listening on
  every address (``0.0.0.0``, ``::``) also answers any IP address (no DNS name is involved,
  so nothing can rebind) and the machine's own host name.
* **Origin.** A change (POST, PUT, PATCH, DELETE) that carries an ``Origin`` must come from
  this server's own origin or one of ``http.cors_origins``, else 403: a page elsewhere
  cannot post a report or clear a fault, even one the browser would send without asking
  (a form, ``fetch`` with ``no-cors``). No ``Origin``: not a browser (curl, a PLC gateway).
* **Headers on every answer.** ``X-Frame-Options: DENY``, ``X-Content-Type-Options: nosniff``,
  ``Referrer-Policy: no-referrer``, and a Content-Security-Policy: ``default-src 'none';
  frame-ancestors 'none'`` for data, and for an HTML page ``default-src 'self'`` with the
  page's own inline scripts and styles allowed by their SHA-256 (the Swagger UI page has one
  script, the shift report one style sheet; the dashboard none) and ``data:`` images (the
  report's charts). No page can be framed, so "Clear fault" cannot be clickjacked.
"""

from __future__ import annotations

import base64
import hashlib
import ipaddress
import json
import re
import socket
from collections.abc import Iterable
from typing import Any

from faultledger.errors import Reason
from faultledger.http.errors import STATUS, body

MUTATIONS = frozenset({"POST", "PUT", "PATCH", "DELETE"})
LOOPBACK_NAMES = ("localhost", "127.0.0.1", "[::1]")
WILDCARD = ("0.0.0.0", "::", "")
COMMON_HEADERS = [
    (b"x-frame-options", b"DENY"),
    (b"x-content-type-options", b"nosniff"),
    (b"referrer-policy", b"no-referrer"),
]
DATA_POLICY = b"default-src 'none'; frame-ancestors 'none'"
PAGE_POLICY = ("default-src 'self'; script-src 'self'{scripts}; style-src 'self'{styles}; "
               "img-src 'self' data:; object-src 'none'; base-uri 'none'; "
               "form-action 'self'; frame-ancestors 'none'")
_INLINE = {
    "scripts": re.compile(r"<script(?![^>]*\bsrc\s*=)[^>]*>(.*?)</script\s*>", re.S | re.I),
    "styles": re.compile(r"<style[^>]*>(.*?)</style\s*>", re.S | re.I),
}


def page_policy(html: str) -> str:
    """The CSP of one HTML page: itself and its inline scripts and styles by hash."""
    found = {}
    for kind, pattern in _INLINE.items():
        hashes = sorted({base64.b64encode(hashlib.sha256(text.encode()).digest()).decode()
                         for text in pattern.findall(html)})
        found[kind] = "".join(f" 'sha256-{value}'" for value in hashes)
    return PAGE_POLICY.format(**found)


def _split(host: str) -> tuple[str, int | None]:
    """``name[:port]`` or ``[v6][:port]`` → (lowercase name, port or None)."""
    host = host.strip().lower()
    if host.startswith("["):
        name, _, rest = host.partition("]")
        port = rest[1:] if rest.startswith(":") else ""
        name += "]"
    else:
        name, _, port = host.partition(":")
    return name, (int(port) if port.isdigit() and len(port) <= 5 else None)


def _is_address(name: str) -> bool:
    try:
        ipaddress.ip_address(name.strip("[]"))
    except ValueError:
        return False
    return True


class AllowedHosts:
    """The ``Host`` values this server answers (module docstring)."""

    def __init__(self, listen_host: str, port: int, extra: Iterable[str] = ()) -> None:
        self.port = port
        self.any = False
        self.any_address = listen_host in WILDCARD
        self.exact: set[tuple[str, int]] = set()
        self.names: set[str] = set()
        """Names allowed with any port (entries given without one)."""
        listen = f"[{listen_host}]" if ":" in listen_host else listen_host
        own = [*LOOPBACK_NAMES, listen.lower()]
        if self.any_address:
            own.append(socket.gethostname().lower())
        for name in own:
            self.exact.add((name, port))
        for entry in extra:
            if entry == "*":
                self.any = True
                continue
            name, entry_port = _split(entry)
            if entry_port is None:
                self.names.add(name)
            else:
                self.exact.add((name, entry_port))
        self.shown = ", ".join(sorted({f"{n}:{p}" for n, p in self.exact} | self.names))

    def allows(self, host: str | None) -> bool:
        if self.any:
            return True
        if not host:
            return False  # HTTP/1.1 requires it; h11 refuses a request without one
        name, port = _split(host)
        if port is None:
            if ":" in host.rpartition("]")[2]:
                return False  # a port that is not a number
            port = 80
        return ((name, port) in self.exact or name in self.names
                or (self.any_address and _is_address(name)))


class BrowserGuard:
    """ASGI middleware: the Host and Origin checks and the headers of every answer."""

    def __init__(self, app: Any, hosts: AllowedHosts, cors_origins: Iterable[str]) -> None:
        self.app = app
        self.hosts = hosts
        self.origins = frozenset(origin.rstrip("/").lower() for origin in cors_origins)

    async def __call__(self, scope: dict[str, Any], receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        host = origin = None
        for name, value in scope.get("headers", ()):
            if name == b"host":
                host = value.decode("latin-1")
            elif name == b"origin":
                origin = value.decode("latin-1")
        if not self.hosts.allows(host):
            await _refuse(send, Reason.INVALID, (
                f"this server answers only for the host names {self.hosts.shown} "
                f"(http.allowed_hosts), not {_shown(host)}: a page from another name that "
                "resolves to this machine is refused (DNS rebinding)"), "invalid-host")
            return
        if scope.get("method") in MUTATIONS and origin is not None:
            own = f"{scope.get('scheme', 'http')}://{host}".lower()
            if origin.rstrip("/").lower() not in {own, *self.origins}:
                await _refuse(send, Reason.FORBIDDEN, (
                    f"a change requested by a page from {_shown(origin)} is refused: only "
                    f"this server's own pages ({own}) and http.cors_origins may make "
                    "changes from a browser"), "forbidden-origin")
                return
        await self.app(scope, receive, _Headers(send))


class _Headers:
    """Adds the common headers to an answer, and the CSP (an HTML page's is computed from
    its body, which is held until it is complete: the pages are small)."""

    def __init__(self, send: Any) -> None:
        self.send = send
        self.start: dict[str, Any] | None = None
        self.parts: list[bytes] = []

    async def __call__(self, message: dict[str, Any]) -> None:
        if message["type"] == "http.response.start":
            headers = [(k, v) for k, v in message.get("headers", ())
                       if k not in (b"x-frame-options", b"content-security-policy")]
            headers += COMMON_HEADERS
            kind = next((v for k, v in headers if k == b"content-type"), b"")
            message = {**message, "headers": headers}
            if kind.startswith(b"text/html"):
                self.start = message
                return
            headers.append((b"content-security-policy", DATA_POLICY))
            await self.send(message)
            return
        if self.start is not None and message["type"] == "http.response.body":
            self.parts.append(message.get("body", b""))
            if message.get("more_body", False):
                return
            page = b"".join(self.parts)
            policy = page_policy(page.decode("utf-8", "replace")).encode()
            start, self.start = self.start, None
            start["headers"] = [*start["headers"], (b"content-security-policy", policy)]
            await self.send(start)
            await self.send({"type": "http.response.body", "body": page, "more_body": False})
            return
        await self.send(message)


def _shown(text: str | None) -> str:
    if text is None:
        return "no Host header"
    return repr(text[:80] + ("…" if len(text) > 80 else ""))


async def _refuse(send: Any, reason: Reason, message: str, error_code: str) -> None:
    payload = json.dumps(body(reason, message, error_code=error_code)).encode()
    await send({"type": "http.response.start", "status": STATUS[reason],
                "headers": [(b"content-type", b"application/json"),
                            (b"content-length", str(len(payload)).encode()),
                            *COMMON_HEADERS, (b"content-security-policy", DATA_POLICY)]})
    await send({"type": "http.response.body", "body": payload})
