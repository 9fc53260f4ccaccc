"""``GET /api/v1/stats`` (every figure of docs/statistics.md, the numbers of `faultledger
stats --json`) and ``GET /api/v1/shift-report`` (the report of `faultledger report-shift
--html`, or its figures as JSON for the dashboard)."""

from __future__ import annotations

from collections.abc import Iterator
from datetime import datetime
from typing import Annotated

from fastapi import APIRouter, Depends, Query
from fastapi.responses import Response

from faultledger.domain.periods import PERIOD_KINDS
from faultledger.domain.stat_rows import GROUP_KEYS, StatsRow
from faultledger.errors import InvalidInputError
from faultledger.http.context import Context
from faultledger.http.heavy import SlotResponse, json_bytes, json_items
from faultledger.service import times
from faultledger.service.exports import stats_csv
from faultledger.service.statistics import StatsBudget
from faultledger.service.tokens import Permission, Principal

CSV_CHUNK = 500
"""Rows per piece of a CSV answer."""


def csv_chunks(rows: list[StatsRow], groups: list[str]) -> Iterator[bytes]:
    """The CSV of ``stats_csv`` (the CLI's), ``CSV_CHUNK`` rows at a time, the header once."""
    for start in range(0, max(len(rows), 1), CSV_CHUNK):
        text = stats_csv(rows[start:start + CSV_CHUNK], groups)
        yield (text if start == 0 else text.split("\n", 1)[1]).encode()


def router(context: Context) -> APIRouter:
    api = APIRouter(prefix="/api/v1", tags=["statistics"])
    ledger = context.ledger
    read = Depends(context.auth.need(Permission.READ))

    def moment(text: str | None, name: str) -> datetime | None:
        return times.parse_time(text, name, context.calendar)

    settings = context.settings
    budget = StatsBudget(settings.max_stats_rows, settings.max_stats_records,
                         "http.max_stats_rows", "http.max_stats_records")

    @api.get("/stats", summary="Figures per period (and group)", response_model=None,
             responses={200: {"content": {"application/json": {}, "text/csv": {}}}})
    async def stats(
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
    ) -> Response:
        groups = group_by or []
        start, end = moment(since, "since"), times.parse_time(until, "until", context.calendar,
                                                               upper=True)
        at = moment(as_of, "as_of")

        def produce() -> Iterator[bytes]:
            # In the heavy pool: at most http.max_stats_rows rows and max_stats_records
            # records read (the budget refuses more before doing the work), sent in chunks.
            rows = ledger.stats(by, start, end, code, groups, calendar=context.calendar,
                                as_of=at, budget=budget)
            if format == "csv":
                return csv_chunks(rows, groups)
            return json_items(rows, StatsRow.as_dict)

        return SlotResponse(context.heavy, produce,
                            "text/csv" if format == "csv" else "application/json")

    @api.get("/shift-report", summary="The end-of-shift report as HTML or JSON",
             response_model=None, responses={200: {"content": {"text/html": {}}}})
    async def shift_report(
        shift: Annotated[str | None, Query(
            description="shift instance, e.g. 2026-11-21/night; default the last completed")
        ] = None,
        as_of: str | None = None,
        format: Annotated[str, Query(pattern="^(html|json)$", description=(
            "html: the report of `report-shift --html`; json: its figures (the dashboard)"))
        ] = "html",
        _: Principal = read,
    ) -> Response:
        at = moment(as_of, "as_of")

        def produce() -> Iterator[bytes]:
            # The same builder as `report-shift` (faultledger.reports.shift); the HTML module
            # is imported only for HTML, so matplotlib loads only when a chart is drawn.
            from faultledger.reports.shift import as_dict, build_report

            try:
                report = build_report(ledger, context.calendar, shift, at)
            except ValueError as error:
                raise InvalidInputError(str(error)) from None
            if format == "json":
                return iter([json_bytes(as_dict(report))])
            from faultledger.reports.shift_html import html

            return iter([html(report).encode()])

        return SlotResponse(context.heavy, produce,
                            "application/json" if format == "json" else "text/html")

    return api
