"""The fleet central's routes (docs/fleet.md): robots push their logs, supervisors see how far
behind each one is, a robot compares what the central holds with its own log."""

from __future__ import annotations

import json
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Header, Query, Request
from fastapi.responses import JSONResponse

from faultledger.domain.fleet import BatchError, parse_record
from faultledger.domain.validation import shown
from faultledger.errors import Reason
from faultledger.http.context import Context
from faultledger.http.errors import ApiError
from faultledger.service import fleet
from faultledger.service.tokens import Permission, Principal, Role

REFUSAL_STATUS = {
    "invalid-request": 400,
    "forbidden": 403,
    "unknown-ledger": 404,
    "record-differs": 409,
    "chain-gap": 409,
    "robot-differs": 409,
    "broken-chain": 422,
    "unreadable-record": 422,
}


def refusal(error: BatchError) -> JSONResponse:
    """A refused batch: ``{"error", "message", "seq"?, "last_seq"?}``; nothing was stored."""
    body: dict[str, Any] = {"error": error.code, "message": str(error),
                            "reason": str(Reason.INVALID)}
    if error.seq is not None:
        body["seq"] = error.seq
    if error.last_seq is not None:
        body["last_seq"] = error.last_seq
    return JSONResponse(body, status_code=REFUSAL_STATUS.get(error.code, 400))


def _batch(body: Any) -> fleet.PushBatch:
    if not isinstance(body, dict):
        raise BatchError("invalid-request", f"the body must be a JSON object, got {shown(body)}")
    unknown = sorted(set(body) - {"robot_id", "ledger_id", "head_seq", "records"})
    if unknown:
        raise BatchError("invalid-request", f"unknown field {shown(unknown[0])}; the fields are "
                         "robot_id, ledger_id, head_seq, records")
    for name in ("robot_id", "ledger_id", "head_seq", "records"):
        if name not in body:
            raise BatchError("invalid-request", f"{name} is required")
    records, head_seq = body["records"], body["head_seq"]
    if not isinstance(records, list):
        raise BatchError("invalid-request", "records must be a list")
    if isinstance(head_seq, bool) or not isinstance(head_seq, int) or head_seq < 0:
        raise BatchError("invalid-request", f"head_seq must be a seq number, got "
                         f"{shown(head_seq)}")
    if len(records) > fleet.MAX_BATCH_RECORDS:
        raise BatchError("invalid-request", f"{len(records)} records in one batch; at most "
                         f"{fleet.MAX_BATCH_RECORDS}")
    return fleet.PushBatch(body["robot_id"], body["ledger_id"], head_seq,
                           [parse_record(raw, i) for i, raw in enumerate(records)])


def _may_push(principal: Principal, robot_id: object) -> None:
    if principal.role is Role.ROBOT and principal.name != robot_id:
        raise BatchError("forbidden", f"token {principal.name!r} may push only the logs of "
                         f"robot {principal.name}, not {shown(robot_id)}")


def router(context: Context) -> APIRouter:
    api = APIRouter(prefix="/api/v1/fleet", tags=["fleet"])
    push_permission = Depends(context.auth.need(Permission.PUSH))

    def store(raw: bytes, principal: Principal) -> JSONResponse:
        try:
            try:
                body = json.loads(raw)
            except ValueError as error:
                raise BatchError("invalid-request", f"the body is not JSON: {error}") from None
            if isinstance(body, dict):
                _may_push(principal, body.get("robot_id"))
            answer = context.robot_logs().push(_batch(body))
        except BatchError as error:
            return refusal(error)
        return JSONResponse({"robot_id": answer.robot_id, "ledger_id": answer.ledger_id,
                             "last_seq": answer.last_seq, "last_hash": answer.last_hash,
                             "stored": answer.stored, "ignored": answer.ignored})

    @api.post("/records", summary="Push a batch of one robot log's records, verbatim "
              "(role robot: its own logs only)", response_model=None,
              openapi_extra={"requestBody": {"required": True, "content": {
                  "application/json": {"schema": {"type": "object"}}}}})
    async def push(request: Request, principal: Principal = push_permission) -> JSONResponse:
        if context.read_only:
            raise ApiError(Reason.UNAVAILABLE, "this server is read-only (a follower); push "
                           "to the central that writes the database")
        raw = await request.body()
        async with context.pushes.slot():
            return await context.pushes.call(store, raw, principal)

    @api.get("/robots", summary="Every robot log the central holds, and how far behind it is "
             "(role robot: its own logs)")
    def robots(authorization: Annotated[str | None, Header()] = None) -> dict[str, Any]:
        principal = context.auth.principal(authorization)
        if not (principal.may(Permission.READ) or principal.may(Permission.PUSH)):
            raise ApiError(Reason.FORBIDDEN, f"token {principal.name!r} has role "
                           f"{principal.role.value}, which may not list robot logs")
        only = None if principal.may(Permission.READ) else principal.name
        return {"items": [{
            "robot_id": c.robot_id, "ledger_id": c.ledger_id, "last_seq": c.last_seq,
            "last_hash": c.last_hash, "records": c.records,
            "last_pushed_at": c.last_pushed_at.isoformat().replace("+00:00", "Z"),
            "lag_seconds": c.lag_seconds,
            "complete_until": None if c.complete_until is None
            else c.complete_until.isoformat().replace("+00:00", "Z"),
            "lag_records": c.lag_records,
        } for c in context.robot_logs().robots(robot_id=only)]}

    @api.get("/records", summary="Seqs and hashes of one log as the central holds it "
             "(what `verify --central` compares)", response_model=None)
    def hashes(ledger_id: Annotated[str, Query(max_length=64)],
               after_seq: Annotated[int, Query(ge=0, le=2**63 - 1)] = 0,
               limit: Annotated[int, Query(ge=1, le=fleet.MAX_HASH_PAGE)] = fleet.MAX_HASH_PAGE,
               authorization: Annotated[str | None, Header()] = None) -> JSONResponse:
        principal = context.auth.principal(authorization)
        if not (principal.may(Permission.READ) or principal.may(Permission.PUSH)):
            raise ApiError(Reason.FORBIDDEN, f"token {principal.name!r} has role "
                           f"{principal.role.value}, which may not read fleet records")
        try:
            robot_id, page, last_seq = context.robot_logs().chain_hashes(ledger_id, after_seq,
                                                                         limit)
            if not principal.may(Permission.READ):
                _may_push(principal, robot_id)
        except BatchError as error:
            return refusal(error)
        return JSONResponse({"robot_id": robot_id, "ledger_id": ledger_id,
                             "last_seq": last_seq,
                             "items": [{"seq": seq, "hash": digest} for seq, digest in page]})

    return api
