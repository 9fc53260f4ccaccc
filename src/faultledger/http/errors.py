"""Every failure as JSON with a machine-readable reason (docs/http.md, "Errors").

The body is ``{"reason", "message"}`` plus medkit's own keys (``error_code``, ``message``) so a
medkit client understands it too. The status code follows the reason: a client branches on it
without parsing text. FastAPI's 422 for a bad parameter becomes 400 ``invalid``; an unforeseen
exception becomes 500 ``internal`` with one line, never a traceback or an HTML page.
"""

from __future__ import annotations

import logging
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from faultledger.domain.validation import shown
from faultledger.errors import FaultLedgerError, Reason

log = logging.getLogger(__name__)

STATUS: dict[str, int] = {
    Reason.INVALID: 400,
    Reason.UNAUTHORIZED: 401,
    Reason.FORBIDDEN: 403,
    Reason.NOT_FOUND: 404,
    Reason.DUPLICATE: 409,
    Reason.CONFLICT: 409,
    Reason.TOO_LARGE: 413,
    Reason.INTERNAL: 500,
    Reason.UNAVAILABLE: 503,
}
MEDKIT_CODES: dict[str, str] = {
    Reason.INVALID: "invalid-parameter",
    Reason.UNAUTHORIZED: "unauthorized",
    Reason.FORBIDDEN: "forbidden",
    Reason.NOT_FOUND: "resource-not-found",
    Reason.DUPLICATE: "conflict",
    Reason.CONFLICT: "conflict",
    Reason.TOO_LARGE: "payload-too-large",
    Reason.INTERNAL: "internal-error",
    Reason.UNAVAILABLE: "service-unavailable",
}


class ApiError(Exception):
    """An answer other than success, raised anywhere in a route."""

    def __init__(self, reason: str, message: str, headers: dict[str, str] | None = None,
                 parameters: dict[str, Any] | None = None, error_code: str | None = None
                 ) -> None:
        super().__init__(message)
        self.reason = Reason(reason)
        self.message = message
        self.headers = headers
        self.parameters = parameters
        self.error_code = error_code
        """medkit's own code where it is more precise than the reason's (entity-not-found)."""


def body(reason: str, message: str, parameters: dict[str, Any] | None = None,
         error_code: str | None = None) -> dict[str, Any]:
    found: dict[str, Any] = {"reason": str(reason), "message": message,
                             "error_code": error_code or MEDKIT_CODES.get(reason, str(reason))}
    if parameters:
        found["parameters"] = parameters
    return found


def response(reason: str, message: str, headers: dict[str, str] | None = None,
             parameters: dict[str, Any] | None = None, error_code: str | None = None
             ) -> JSONResponse:
    return JSONResponse(body(reason, message, parameters, error_code),
                        status_code=STATUS.get(reason, 500), headers=headers)


def _validation_message(error: RequestValidationError) -> str:
    problems = []
    for problem in error.errors()[:5]:
        where = ".".join(str(part) for part in problem.get("loc", ()) if part != "body")
        given = problem.get("input")
        text = problem.get("msg", "invalid")
        if problem.get("type") == "json_invalid":
            return "the request body is not valid JSON"
        problems.append(f"{where or 'body'}: {text}"
                        + (f" (got {shown(given)})" if given is not None
                           and not isinstance(given, dict | list) else ""))
    return "; ".join(problems) or "invalid request"


def install(app: FastAPI) -> None:
    @app.exception_handler(ApiError)
    async def api_error(_request: Request, error: ApiError) -> JSONResponse:
        return response(error.reason, error.message, error.headers, error.parameters,
                        error.error_code)

    @app.exception_handler(FaultLedgerError)
    async def ledger_error(_request: Request, error: FaultLedgerError) -> JSONResponse:
        return response(error.reason, str(error))

    @app.exception_handler(RequestValidationError)
    async def invalid(_request: Request, error: RequestValidationError) -> JSONResponse:
        return response(Reason.INVALID, _validation_message(error))

    @app.exception_handler(StarletteHTTPException)
    async def http_error(request: Request, error: StarletteHTTPException) -> JSONResponse:
        if error.status_code == 404:
            return response(Reason.NOT_FOUND, f"no such endpoint: {shown(request.url.path)}")
        if error.status_code == 405:
            return response(Reason.INVALID,
                            f"{request.method} is not allowed on {shown(request.url.path)}")
        reason = {401: Reason.UNAUTHORIZED, 403: Reason.FORBIDDEN, 413: Reason.TOO_LARGE,
                  503: Reason.UNAVAILABLE}.get(error.status_code, Reason.INVALID)
        return response(reason, str(error.detail))

    @app.exception_handler(Exception)
    async def unforeseen(_request: Request, error: Exception) -> JSONResponse:
        log.error("internal error: %s: %s", type(error).__name__, shown(str(error), 200))
        log.debug("internal error", exc_info=True)
        return response(Reason.INTERNAL,
                        f"internal error: {type(error).__name__}: {shown(str(error), 200)}")
