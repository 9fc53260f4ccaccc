"""``GET /api/v1/stats`` (every figure of docs/statistics.md, the numbers of `faultledger
stats --json`) and ``GET /api/v1/shift-report`` (the report of `faultledger report-shift
--html`, or its figures as JSON for the dashboard)."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Query
from fastapi.responses import HTMLResponse, Response

from faultledger.domain.periods import PERIOD_KINDS
from faultledger.domain.stat_rows import GROUP_KEYS
from faultledger.errors import InvalidInputError
from faultledger.http.context import Context
from faultledger.service import times
from faultledger.service.exports import stats_csv
from faultledger.service.tokens import Permission, Principal


def router(context: Context) -> APIRouter:
    api = APIRouter(prefix="/api/v1", tags=["statistics"])
    ledger = context.ledger
    read = Depends(context.auth.need(Permission.READ))

    def moment(text: str | None, name: str) -> datetime | None:
        return times.parse_time(text, name, context.calendar)

    @api.get("/stats", summary="Figures per period (and group)", response_model=None)
    def stats(
        by: Annotated[str, Query(description=f"period: {', '.join(PERIOD_KINDS)}")] = "shift",
        since: Annotated[str | None, Query(
            description="start (inclusive): shift id, date or date-time; default until - "
            "24 h")] = None,
        until: Annotated[str | None, Query(
            description="end (exclusive); a shift id means its end; default: as_of, else "
            "now")] = None,
        code: Annotated[list[str] | None, Query(description="fault code glob (repeatable)")
                        ] = None,
        group_by: Annotated[list[str] | None, Query(
            description=f"{', '.join(GROUP_KEYS)} (repeatable)")] = None,
        as_of: Annotated[str | None, Query(
            description="the moment open episodes end at (default now)")] = None,
        format: Annotated[str, Query(pattern="^(json|csv)$")] = "json",
        _: Principal = read,
    ) -> Any:
        groups = group_by or []
        rows = ledger.stats(by, moment(since, "since"),
                            times.parse_time(until, "until", context.calendar, upper=True),
                            code, groups, calendar=context.calendar,
                            as_of=moment(as_of, "as_of"))
        if format == "csv":
            return Response(stats_csv(rows, groups), media_type="text/csv")
        return {"items": [row.as_dict() for row in rows]}

    @api.get("/shift-report", summary="The end-of-shift report as HTML or JSON",
             response_model=None, responses={200: {"content": {"text/html": {}}}})
    def shift_report(
        shift: Annotated[str | None, Query(
            description="shift instance, e.g. 2026-11-21/night; default the last completed")
        ] = None,
        as_of: str | None = None,
        format: Annotated[str, Query(pattern="^(html|json)$", description=(
            "html: the report of `report-shift --html`; json: its figures (the dashboard)"))
        ] = "html",
        _: Principal = read,
    ) -> Any:
        # The same builder as `report-shift` (faultledger.reports.shift); the HTML module is
        # imported only for HTML, so matplotlib loads only when a chart is drawn.
        from faultledger.reports.shift import as_dict, build_report

        try:
            report = build_report(ledger, context.calendar, shift, moment(as_of, "as_of"))
        except ValueError as error:
            raise InvalidInputError(str(error)) from None
        if format == "json":
            return as_dict(report)
        from faultledger.reports.shift_html import html

        return HTMLResponse(html(report))

    return api
