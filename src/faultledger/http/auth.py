"""Bearer-token authorization per route, and the request size limit (docs/http.md, "Auth").

With no tokens configured the server is open, and it may then only listen on loopback
(``server.check_exposure``): every request acts as ``anonymous`` with every permission.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any

from fastapi import Request

from faultledger.errors import Reason
from faultledger.http.errors import STATUS, ApiError, body
from faultledger.service.tokens import GRANTS, Permission, Principal, Role, TokenBook

ANONYMOUS = Principal("anonymous", Role.ADMIN)

_WHAT = {
    Permission.READ: "read",
    Permission.REPORT: "post reports",
    Permission.CLEAR: "clear faults",
    Permission.ADMINISTER: "administer the ledger",
}


def roles_with(permission: Permission) -> str:
    return " or ".join(role.value for role, grants in GRANTS.items() if permission in grants)


class Authorizer:
    def __init__(self, book: TokenBook) -> None:
        self.book = book

    def principal(self, authorization: str | None) -> Principal:
        if not self.book:
            return ANONYMOUS
        challenge = {"WWW-Authenticate": 'Bearer realm="faultledger"'}
        if not authorization:
            raise ApiError(Reason.UNAUTHORIZED, "this server needs a bearer token: send "
                           "'Authorization: Bearer <token>' (faultledger token create)",
                           challenge)
        scheme, _, token = authorization.partition(" ")
        if scheme.lower() != "bearer" or not token.strip():
            raise ApiError(Reason.UNAUTHORIZED, "the Authorization header must be "
                           "'Bearer <token>'", challenge)
        found = self.book.find(token.strip())
        if found is None:
            raise ApiError(Reason.UNAUTHORIZED, "unknown or revoked token", challenge)
        return found

    def need(self, permission: Permission) -> Callable[[Request], Awaitable[Principal]]:
        """A FastAPI dependency: the caller, when allowed ``permission``."""
        async def dependency(request: Request) -> Principal:
            principal = self.principal(request.headers.get("authorization"))
            if not principal.may(permission):
                raise ApiError(Reason.FORBIDDEN,
                               f"token {principal.name!r} has role {principal.role.value}, "
                               f"which may not {_WHAT[permission]} (needs "
                               f"{roles_with(permission)})")
            return principal
        return dependency


class BodyLimit:
    """ASGI middleware: a request body over ``limit`` bytes is answered 413 ``too_large``,
    whether it announces its length or streams it in chunks."""

    def __init__(self, app: Any, limit: int) -> None:
        self.app = app
        self.limit = limit

    async def __call__(self, scope: dict[str, Any], receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        for name, value in scope.get("headers", ()):
            if name == b"content-length" and value.isdigit() and int(value) > self.limit:
                await self._refuse(send)
                return
        seen = 0
        refused = False

        async def limited() -> dict[str, Any]:
            nonlocal seen, refused
            message: dict[str, Any] = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.limit:
                    refused = True
                    raise _TooLarge
            return message

        replaced = False

        async def checked_send(message: dict[str, Any]) -> None:
            """Whatever the app answers to a body it could not finish reading (frameworks
            turn the interruption into their own 400), the client gets the 413."""
            nonlocal replaced
            if refused:
                if not replaced:
                    replaced = True
                    await self._refuse(send)
                return
            await send(message)

        try:
            await self.app(scope, limited, checked_send)
        except _TooLarge:
            if not replaced:
                await self._refuse(send)

    async def _refuse(self, send: Any) -> None:
        import json
        payload = json.dumps(body(Reason.TOO_LARGE, f"the request body is larger than "
                                  f"{self.limit} bytes (http.max_body_bytes)")).encode()
        await send({"type": "http.response.start", "status": STATUS[Reason.TOO_LARGE],
                    "headers": [(b"content-type", b"application/json"),
                                (b"content-length", str(len(payload)).encode()),
                                (b"connection", b"close")]})
        await send({"type": "http.response.body", "body": payload})


class _TooLarge(Exception):
    pass
