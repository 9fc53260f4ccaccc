"""Bearer-token authorization per route, and the request size limit (docs/http.md, "Auth").

With no tokens configured the server is open, and it may then only listen on loopback
(``server.check_exposure``): every request acts as ``anonymous`` with every permission. The
tokens follow the token file while the server runs (``service.tokens.TokenWatcher``); an
expired token is refused with the time it expired.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from datetime import UTC, datetime
from typing import Annotated, Any

from fastapi import Request, Security
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from starlette.datastructures import Headers

from faultledger.errors import Reason
from faultledger.http.errors import STATUS, ApiError, body, response
from faultledger.service.tokens import GRANTS, Permission, Principal, Role, TokenBook, utc_text

ANONYMOUS = Principal("anonymous", Role.ADMIN)
CHALLENGE = 'Bearer realm="faultledger"'
BEARER = HTTPBearer(auto_error=False, scheme_name="bearer", description=(
    "A token from `faultledger token create` (only its role's routes answer). Without "
    "tokens configured the server is open to loopback clients and needs none."))
Declared = Annotated[HTTPAuthorizationCredentials | None, Security(BEARER)]
"""Declared in the OpenAPI document (Swagger UI's Authorize); the check itself is
``Authorizer.allowed``, which reads the header and gives the server's own messages."""

_WHAT = {
    Permission.READ: "read",
    Permission.REPORT: "post reports",
    Permission.CLEAR: "clear faults",
    Permission.ACKNOWLEDGE: "acknowledge or shelve faults",
    Permission.ADMINISTER: "administer the ledger",
    Permission.PUSH: "push a robot's log to the fleet central",
}


def roles_with(permission: Permission) -> str:
    return " or ".join(role.value for role, grants in GRANTS.items() if permission in grants)


class Authorizer:
    """Decides who a request is. ``book`` is replaced whole when the token file changes
    (``service.tokens.TokenWatcher``); a request reads it once."""

    def __init__(self, book: TokenBook, *, open_without_tokens: bool = True) -> None:
        self.book = book
        self.open_without_tokens = open_without_tokens
        """Loopback only: with no token at all every request is ``ANONYMOUS``. A server
        listening beyond loopback whose tokens were all revoked refuses every request."""

    def replace(self, book: TokenBook) -> None:
        self.book = book

    def principal(self, authorization: str | None) -> Principal:
        book = self.book
        challenge = {"WWW-Authenticate": CHALLENGE}
        if not book:
            if self.open_without_tokens:
                return ANONYMOUS
            raise ApiError(Reason.UNAUTHORIZED, "this server listens beyond loopback and has "
                           "no tokens left (all were revoked): create one "
                           "(faultledger token create)", challenge)
        if not authorization:
            raise ApiError(Reason.UNAUTHORIZED, "this server needs a bearer token: send "
                           "'Authorization: Bearer <token>' (faultledger token create)",
                           challenge)
        scheme, _, token = authorization.partition(" ")
        if scheme.lower() != "bearer" or not token.strip():
            raise ApiError(Reason.UNAUTHORIZED, "the Authorization header must be "
                           "'Bearer <token>'", challenge)
        found = book.find(token.strip())
        if found is None:
            raise ApiError(Reason.UNAUTHORIZED, "unknown or revoked token", challenge)
        if found.expires_at is not None and found.expired(datetime.now(UTC)):
            raise ApiError(Reason.UNAUTHORIZED,
                           f"token {found.principal.name!r} expired at "
                           f"{utc_text(found.expires_at)}; ask for a new one (faultledger "
                           "token create --expires …)",
                           {"WWW-Authenticate": CHALLENGE + ', error="invalid_token", '
                            'error_description="the token expired"'})
        return found.principal

    def allowed(self, authorization: str | None, permission: Permission) -> Principal:
        """The caller, when allowed ``permission``; else ``ApiError`` 401 or 403."""
        principal = self.principal(authorization)
        if not principal.may(permission):
            raise ApiError(Reason.FORBIDDEN,
                           f"token {principal.name!r} has role {principal.role.value}, "
                           f"which may not {_WHAT[permission]} (needs "
                           f"{roles_with(permission)})")
        return principal

    def need(self, permission: Permission) -> Callable[..., Awaitable[Principal]]:
        """A FastAPI dependency: the caller, when allowed ``permission``."""
        async def dependency(request: Request, _declared: Declared) -> Principal:
            return self.allowed(request.headers.get("authorization"), permission)
        return dependency


class Guarded:
    """ASGI middleware: the exact ``paths`` (``/openapi.json``, ``/docs``: the API's
    description) need ``permission`` like any route, so once tokens exist they answer 401
    without one. Routes FastAPI adds itself take no dependencies, hence a middleware."""

    def __init__(self, app: Any, authorizer: Authorizer, paths: frozenset[str],
                 permission: Permission = Permission.READ) -> None:
        self.app = app
        self.authorizer = authorizer
        self.paths = paths
        self.permission = permission

    async def __call__(self, scope: dict[str, Any], receive: Any, send: Any) -> None:
        if scope["type"] == "http" and scope["path"] in self.paths:
            try:
                self.authorizer.allowed(Headers(scope=scope).get("authorization"),
                                        self.permission)
            except ApiError as error:
                answer = response(error.reason, error.message, error.headers)
                await answer(scope, receive, send)
                return
        await self.app(scope, receive, send)


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
