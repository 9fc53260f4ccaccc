"""``/health``: is the ledger serving, how far is its log, and whose log it is (robot_id,
ledger_id: a fleet tool tells robots apart without a token)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from faultledger.http.context import Context
from faultledger.version import version


def router(context: Context) -> APIRouter:
    api = APIRouter(tags=["system"])

    @api.get("/health", summary="Liveness, the head of the log and whose log it is "
             "(no token needed)")
    def health() -> dict[str, Any]:
        ledger = context.ledger
        identity = ledger.identity
        return {"status": "ok", "version": version(), "last_seq": ledger.last_seq,
                "read_only": context.read_only, "stream_clients": context.hub.clients,
                "robot_id": None if identity is None else identity.robot_id,
                "ledger_id": None if identity is None else identity.ledger_id}

    return api
