"""Acknowledge, shelve and unshelve over HTTP (docs/http.md, "The operator's day"): the
operator role, the token's name as actor, the same rules and messages as the CLI's."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body, Depends
from pydantic import BaseModel, ConfigDict, Field

from faultledger.errors import Reason
from faultledger.http import medkit
from faultledger.http.context import Context
from faultledger.http.errors import ApiError
from faultledger.http.routes.faults import not_found, writable
from faultledger.service.results import OperatorResult
from faultledger.service.tokens import Permission, Principal


class AcknowledgeIn(BaseModel):
    model_config = ConfigDict(extra="forbid")

    note: Any = ""
    """What was seen or done, for the shift handover."""


class ShelveIn(BaseModel):
    model_config = ConfigDict(extra="forbid", populate_by_name=True)

    duration: Any = Field(alias="for")
    """How long: ``2h``, ``90m``, ``1h30m``, ``1d`` (at most 30 days), or seconds."""
    reason: Any = ""


class UnshelveIn(BaseModel):
    model_config = ConfigDict(extra="forbid")

    reason: Any = ""


def answer(code: str, result: OperatorResult) -> dict[str, Any]:
    """200 with what was recorded (``recorded: false`` for a repeated acknowledgement);
    404 for an unknown fault, 409 when its state refuses, 400 for bad input."""
    if not result.success:
        if result.reason == Reason.NOT_FOUND:
            raise not_found(code)
        raise ApiError(result.reason or Reason.INVALID, result.message,
                       parameters={"fault_code": code})
    body: dict[str, Any] = {"message": result.message, "recorded": result.seq is not None,
                            "seq": result.seq}
    if result.fault is not None:
        body["fault"] = medkit.fault_item(result.fault)
    return body


def router(context: Context) -> APIRouter:
    api = APIRouter(prefix="/api/v1", tags=["the operator's day"])
    ledger = context.ledger
    operate = Depends(context.auth.need(Permission.ACKNOWLEDGE))

    @api.post("/faults/{fault_code}/ack", summary="Acknowledge the fault's current episode "
              "(the status stays)")
    def acknowledge(fault_code: str,
                    given: Annotated[AcknowledgeIn | None, Body()] = None,
                    principal: Principal = operate) -> dict[str, Any]:
        writable(context)
        note = (given or AcknowledgeIn()).note
        return answer(fault_code, ledger.acknowledge(fault_code, principal.name, note))

    @api.post("/faults/{fault_code}/shelve", summary="Hide a known nuisance from lists, the "
              "dashboard and alerts for a while")
    def shelve(fault_code: str, given: ShelveIn,
               principal: Principal = operate) -> dict[str, Any]:
        writable(context)
        return answer(fault_code, ledger.shelve(fault_code, given.duration, principal.name,
                                                given.reason))

    @api.post("/faults/{fault_code}/unshelve", summary="End the fault's shelving now")
    def unshelve(fault_code: str, given: Annotated[UnshelveIn | None, Body()] = None,
                 principal: Principal = operate) -> dict[str, Any]:
        writable(context)
        reason = (given or UnshelveIn()).reason
        return answer(fault_code, ledger.unshelve(fault_code, principal.name, reason))

    return api
