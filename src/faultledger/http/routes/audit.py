"""``GET /api/v1/history`` (the audit log, paged by seq either way, JSON / CSV / JSON Lines
with hashes) and ``GET /api/v1/state-at`` (time travel): the CLI's `history` and `state-at`
over HTTP."""

from __future__ import annotations

import io
from collections.abc import Iterator
from enum import StrEnum
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Query
from fastapi.responses import Response

from faultledger.domain.identity import LedgerIdentity
from faultledger.errors import InvalidInputError
from faultledger.http import medkit
from faultledger.http.context import Context
from faultledger.http.heavy import SlotResponse, json_bytes, json_items
from faultledger.service import times
from faultledger.service.audit import count_history, export_history, seq_recorded_by
from faultledger.service.exports import Writer, export_row, write_csv, write_jsonl
from faultledger.service.tokens import Permission, Principal
from faultledger.store.event_log import StoredRecord

PAGE = 1000
MOST = 10_000
STREAM_CHUNK = 500
"""Rows per write of a CSV / JSON Lines answer: a long export streams in pieces."""


class Format(StrEnum):
    json = "json"
    csv = "csv"
    jsonl = "jsonl"


class Order(StrEnum):
    asc = "asc"
    desc = "desc"


def _chunks(rows: Iterator[StoredRecord], write: Writer, identity: LedgerIdentity | None
            ) -> Iterator[str]:
    """Text of ``write(rows, out, identity)`` in pieces of ``STREAM_CHUNK`` rows; the CSV
    header once."""
    first = True
    while True:
        batch = [row for _, row in zip(range(STREAM_CHUNK), rows, strict=False)]
        if not batch and not first:
            return
        out = io.StringIO()
        write(batch, out, identity)
        text = out.getvalue()
        if not first and write is write_csv:
            text = text.split("\n", 1)[1]  # the header only once
        first = False
        yield text
        if len(batch) < STREAM_CHUNK:
            return


def router(context: Context) -> APIRouter:
    api = APIRouter(prefix="/api/v1", tags=["audit"])
    ledger = context.ledger
    read = Depends(context.auth.need(Permission.READ))

    @api.get("/history", summary="Log records (the audit trail), paged by seq either way",
             response_model=None)
    async def history(
        code: Annotated[list[str] | None, Query(
            description="fault code or case-sensitive glob (repeatable: any)")] = None,
        source: str | None = None,
        kind: Annotated[list[str] | None, Query(description="record kind (repeatable)")] = None,
        since: Annotated[str | None, Query(
            description="occurred_at from (inclusive): shift id, date or date-time")] = None,
        until: Annotated[str | None, Query(
            description="occurred_at before (exclusive); a shift id means its end")] = None,
        from_seq: Annotated[int | None, Query(ge=1)] = None,
        to_seq: Annotated[int | None, Query(ge=1)] = None,
        after_seq: Annotated[int, Query(ge=0, description="page: records after this seq")] = 0,
        before_seq: Annotated[int | None, Query(
            ge=1, description="page: records before this seq (with order=desc: the "
            "next_before_seq of the page before)")] = None,
        order: Annotated[Order, Query(
            description="json: asc (oldest first, the default) or desc (newest first)")
        ] = Order.asc,
        total: Annotated[bool, Query(
            description="json: add the number of records the filters match (every page)")
        ] = False,
        limit: Annotated[int | None, Query(ge=1, le=MOST, description=(
            f"records per page (json: default {PAGE}); csv/jsonl: all when not given"))] = None,
        format: Format = Format.json,
        _: Principal = read,
    ) -> Response:
        calendar = context.calendar
        if from_seq is not None and to_seq is not None and from_seq > to_seq:
            raise InvalidInputError(f"from_seq {from_seq} is after to_seq {to_seq}: the range "
                                    "is empty")
        if format is not Format.json and (order is Order.desc or total):
            raise InvalidInputError(f"order=desc and total are for JSON pages; a {format} "
                                    "export is every record in seq order")
        filters: dict[str, Any] = {
            "codes": code or None, "source": source, "kinds": kind or (),
            "since": times.parse_time(since, "since", calendar),
            "until": times.parse_time(until, "until", calendar, upper=True),
            "from_seq": from_seq, "to_seq": to_seq,
        }
        # The page cursors narrow the seq range: after_seq from below, before_seq from above.
        first_seq = max(from_seq or 1, after_seq + 1)
        last_seq = (to_seq if before_seq is None
                    else before_seq - 1 if to_seq is None else min(to_seq, before_seq - 1))
        empty = last_seq is not None and first_seq > last_seq  # paged past an end
        paged = {**filters, "from_seq": first_seq, "to_seq": last_seq}

        def select(most: int | None) -> Iterator[StoredRecord]:
            return iter(()) if empty else export_history(
                ledger, limit=most, descending=order is Order.desc, **paged)

        if format is Format.json:
            page = limit or PAGE

            def json_page() -> Iterator[bytes]:
                # In the heavy pool: at most MOST records, sent in chunks.
                rows = list(select(page + 1))
                more = len(rows) > page
                del rows[page:]
                cursor = rows[-1].seq if more and rows else None
                extra: dict[str, Any] = {("next_before_seq" if order is Order.desc
                                          else "next_after_seq"): cursor}
                if total:
                    extra["total"] = count_history(ledger, **filters)
                identity = ledger.identity
                return json_items(rows, lambda row: export_row(row, identity), extra)

            return SlotResponse(context.heavy, json_page, "application/json")

        def export() -> Iterator[bytes]:
            rows_iter = select(limit)
            first_row = next(rows_iter, None)  # bad filters fail here, before any byte is sent

            def all_rows() -> Iterator[StoredRecord]:
                if first_row is not None:
                    yield first_row
                    yield from rows_iter

            write = write_csv if format is Format.csv else write_jsonl
            return (text.encode() for text in _chunks(all_rows(), write, ledger.identity))

        # Every record: a chunk at a time in the heavy pool, other heavy reads between.
        if format is Format.csv:
            return SlotResponse(context.heavy, export, "text/csv",
                                _attachment("history.csv"), per_chunk=True)
        return SlotResponse(context.heavy, export, "application/x-ndjson",
                            _attachment("history.jsonl"), per_chunk=True)

    @api.get("/state-at", summary="Faults as they stood after a seq or at a time",
             response_model=None, responses={200: {"content": {"application/json": {}}}})
    async def state_at(at: Annotated[str, Query(
                           description="a seq number, or a time: shift id, date or date-time")],
                       status: str = "all", _: Principal = read) -> Response:
        moment = times.parse_moment(at, "at", context.calendar)
        wanted = medkit.STATUS_GROUPS.get(status)
        if wanted is None:
            raise InvalidInputError(f"status must be one of {medkit.ALLOWED_STATUS_VALUES}, "
                                    f"got {status[:40]!r}")

        def produce() -> Iterator[bytes]:
            # In the heavy pool: replaying a long log prefix takes a while.
            seq = seq_recorded_by(ledger, moment)
            faults = [f for f in ledger.state_at(seq) if f.status in wanted]
            answer = medkit.fault_list(faults)
            answer["x-medkit"]["seq"] = seq
            return iter([json_bytes(answer)])

        return SlotResponse(context.heavy, produce, "application/json")

    return api


def _attachment(name: str) -> dict[str, str]:
    return {"Content-Disposition": f'attachment; filename="{name}"'}

