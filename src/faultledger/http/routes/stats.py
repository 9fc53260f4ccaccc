"""``GET /api/v1/stats`` (every figure of docs/statistics.md, the numbers of `faultledger
stats --json`) and ``GET /api/v1/shift-report`` (the report of `faultledger report-shift
--html`, or its figures as JSON for the dashboard)."""

from __future__ import annotations

from collections.abc import Iterator
from datetime import UTC, datetime
from typing import Annotated

from fastapi import APIRouter, Depends, Query
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import Response

from faultledger.domain.fleet import robot_id_error
from faultledger.domain.fleet_stats import FLEET_KEYS
from faultledger.domain.periods import PERIOD_KINDS
from faultledger.domain.stat_rows import GROUP_KEYS, StatsRow
from faultledger.domain.validation import shown
from faultledger.errors import InvalidInputError, Reason
from faultledger.http.context import Context
from faultledger.http.errors import ApiError
from faultledger.http.heavy import SlotResponse, json_bytes, json_items
from faultledger.service import times
from faultledger.service.exports import stats_csv
from faultledger.service.fleet import Fleet
from faultledger.service.statistics import StatsBudget
from faultledger.service.tokens import Permission, Principal

CSV_CHUNK = 500
"""Rows per piece of a CSV answer."""


def csv_chunks(rows: list[StatsRow], groups: list[str]) -> Iterator[bytes]:
    """The CSV of ``stats_csv`` (the CLI's), ``CSV_CHUNK`` rows at a time, the header once."""
    for start in range(0, max(len(rows), 1), CSV_CHUNK):
        text = stats_csv(rows[start:start + CSV_CHUNK], groups)
        yield (text if start == 0 else text.split("\n", 1)[1]).encode()


ALL_KEYS = (*GROUP_KEYS, *FLEET_KEYS)


def check_fleet_groups(groups: list[str]) -> None:
    """Refuse unknown or repeated group keys naming every key a central groups by (the log's
    own keys are checked again by the log's ``stats``)."""
    for key in groups:
        if key not in ALL_KEYS or groups.count(key) > 1:
            raise InvalidInputError(f"group_by takes distinct names from {', '.join(ALL_KEYS)}"
                                    f", got {shown(groups)}")


def held_logs(fleet: Fleet, robot: str | None) -> int:
    """How many logs a fleet query reads: a robot the central holds nothing of is 404 naming the
    robots it holds (an invalid name stays 400)."""
    if robot is None:
        return len(fleet.chains())
    problem = robot_id_error(robot)
    if problem is not None:
        raise InvalidInputError(f"robot: {problem}")
    try:
        return len(fleet.chains_of(robot))
    except InvalidInputError as error:
        raise ApiError(Reason.NOT_FOUND, str(error), parameters={"robot": robot}) from None


def shared_budget(budget: StatsBudget, logs: int) -> StatsBudget:
    """One request's limits shared by the robot logs it reads (each log's stats checks its
    own share), so a fleet query does no more work and holds no more rows than one log's."""
    if logs <= 1:
        return budget
    return StatsBudget(max(1, budget.rows // logs), max(1, budget.records // logs),
                       f"{budget.rows_setting} {budget.rows:,} shared by {logs} robot logs",
                       f"{budget.records_setting} {budget.records:,} shared by {logs} robot "
                       "logs")


def iso(moment: datetime) -> str:
    return moment.astimezone(UTC).isoformat().replace("+00:00", "Z")


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
            description=f"{', '.join(ALL_KEYS)} (repeatable; robot, line and site: the "
            "robot logs of a fleet central)")] = None,
        as_of: Annotated[str | None, Query(
            description="the moment open episodes end at (default now)")] = None,
        format: Annotated[str, Query(pattern="^(json|csv)$")] = "json",
        robot: Annotated[str | None, Query(
            description="one robot's log(s) as this fleet central holds them")] = None,
        _: Principal = read,
    ) -> Response:
        groups = group_by or []
        start, end = moment(since, "since"), times.parse_time(until, "until", context.calendar,
                                                               upper=True)
        at = moment(as_of, "as_of")
        if robot is not None or any(key in FLEET_KEYS for key in groups):
            return await fleet_stats(by, start, end, code, groups, at, format, robot)

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

    async def fleet_stats(by: str, start: datetime | None, end: datetime | None,
                          code: list[str] | None, groups: list[str], at: datetime | None,
                          format: str, robot: str | None) -> Response:
        """The robot logs' statistics (Fleet.stats), in the same pool as any statistics.
        Every log's periods end at one ``as_of``, so the rows of one period line up and say
        when they were counted up to (``as_of`` beside the items)."""
        check_fleet_groups(groups)
        fleet = context.robot_logs()
        logs = await run_in_threadpool(held_logs, fleet, robot)
        at = at or datetime.now(UTC)
        shared = shared_budget(budget, logs)

        def produce() -> Iterator[bytes]:
            rows = fleet.stats(by, start, end, code, groups, robot=robot,
                               labels=context.fleet_labels, as_of=at, budget=shared)
            if format == "csv":
                # A robot with a replaced database has a row per log: ledger_id tells them apart.
                keys = [*groups, *(["ledger_id"] if any("ledger_id" in row.group
                                                        for row in rows) else [])]
                return csv_chunks(rows, keys)
            return json_items(rows, StatsRow.as_dict, {"as_of": iso(at)})

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
