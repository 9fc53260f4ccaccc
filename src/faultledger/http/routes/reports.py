"""``POST /api/v1/reports``: FAILED/PASSED reports from sources without ROS (PLC gateways,
scripts), one object or a list, idempotent by ``event_id`` (docs/http.md, "Reports").

Fields are typed loosely here on purpose: the service checks every value and its message is
the one the CLI and the ROS service give (SPEC §4.5).
"""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any

from fastapi import APIRouter, Body, Depends
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict

from faultledger.domain import validation
from faultledger.domain.clock import from_ns
from faultledger.errors import Reason
from faultledger.http.context import Context
from faultledger.http.errors import MEDKIT_CODES, STATUS, ApiError
from faultledger.service.requests import ReportRequest
from faultledger.service.results import ReportResult
from faultledger.service.tokens import Permission, Principal


class ReportIn(BaseModel):
    """One report; unknown fields are refused (a typo must not pass silently)."""

    model_config = ConfigDict(extra="forbid")

    fault_code: Any
    event_type: Any
    severity: Any = 0
    description: Any = ""
    source_id: Any = ""
    event_id: Any = None
    occurred_at: Any = None
    """ISO 8601 with a zone (``2026-11-23T10:00:00.123Z``), or integer nanoseconds since
    the epoch; none: when the server receives it."""


def occurred(value: Any) -> datetime | None:
    if value is None:
        return None
    if isinstance(value, int) and not isinstance(value, bool):
        problem = validation.ns_error("occurred_at", value)
        if problem:
            raise ValueError(problem)
        return from_ns(value)
    if isinstance(value, str):
        try:
            moment = datetime.fromisoformat(value.strip())
        except ValueError:
            raise ValueError(f"occurred_at must be ISO 8601 with a zone "
                             f"(2026-11-23T10:00:00Z) or nanoseconds, got "
                             f"{validation.shown(value)}") from None
        if moment.tzinfo is None:
            raise ValueError(f"occurred_at needs a zone (Z or +hh:mm), got "
                             f"{validation.shown(value)}")
        return moment
    raise ValueError(f"occurred_at must be ISO 8601 text or integer nanoseconds, got "
                     f"{validation.shown(value)}")


def parsed(raw: list[Any]) -> list[ReportIn]:
    """Each element as a ``ReportIn``; the first malformed one is the whole request's error,
    named by its position and field."""
    found = []
    for position, element in enumerate(raw):
        where = "" if len(raw) == 1 else f"report {position}: "
        if not isinstance(element, dict):
            raise ApiError(Reason.INVALID, f"{where}a report must be a JSON object, got "
                           f"{validation.shown(element)}")
        unknown = sorted(set(element) - set(ReportIn.model_fields))
        if unknown:
            raise ApiError(Reason.INVALID, f"{where}unknown field {validation.shown(unknown[0])}"
                           f"; the fields are {', '.join(ReportIn.model_fields)}")
        missing = [name for name in ("fault_code", "event_type") if name not in element]
        if missing:
            raise ApiError(Reason.INVALID, f"{where}{missing[0]} is required")
        found.append(ReportIn.model_validate(element))
    return found


def result_json(result: ReportResult) -> dict[str, Any]:
    return {"accepted": result.accepted, "message": result.message, "seq": result.seq,
            "event_id": result.event_id, "duplicate": result.duplicate,
            "reason": str(result.reason)}


def router(context: Context) -> APIRouter:
    api = APIRouter(prefix="/api/v1", tags=["reports"])
    report_permission = Depends(context.auth.need(Permission.REPORT))
    limit = context.settings.max_reports_per_request

    @api.post("/reports", summary="Record FAILED/PASSED reports (one object or a list)",
              response_model=None)
    def post_reports(body: Annotated[Any, Body(openapi_examples={
                         "one": {"value": {"fault_code": "PLC_DOOR_OPEN", "event_type": "FAILED",
                                           "severity": 2, "description": "door 3 open",
                                           "source_id": "/plc/line3"}}})],
                     principal: Principal = report_permission) -> JSONResponse:
        if context.read_only:
            raise ApiError(Reason.UNAVAILABLE, "this server is read-only (a follower); "
                           "report to the fault manager that writes the database")
        single = not isinstance(body, list)
        items = parsed([body] if single else body)
        if not items:
            raise ApiError(Reason.INVALID, "the list of reports is empty")
        if len(items) > limit:
            raise ApiError(Reason.INVALID, f"{len(items)} reports in one request; at most "
                           f"{limit} (http.max_reports_per_request)")
        results: list[ReportResult | None] = [None] * len(items)
        requests: list[ReportRequest] = []
        positions: list[int] = []
        for index, item in enumerate(items):
            try:
                at = occurred(item.occurred_at)
            except ValueError as error:
                results[index] = ReportResult(False, str(error))
                continue
            source = item.source_id if item.source_id not in (None, "") else (
                f"http:{principal.name}")
            requests.append(ReportRequest(item.fault_code, item.event_type, item.severity,
                                          item.description, source, at, item.event_id))
            positions.append(index)
        for index, result in zip(positions, context.ledger.report_many(requests), strict=True):
            results[index] = result
        answers = [result_json(r) for r in results if r is not None]
        if not single:
            return JSONResponse({"results": answers})
        answer = answers[0]
        if answer["accepted"]:
            return JSONResponse(answer)
        reason = answer["reason"]
        return JSONResponse({**answer, "error_code": MEDKIT_CODES.get(reason, reason)},
                            status_code=STATUS.get(reason, 400))

    return api
