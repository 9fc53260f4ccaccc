"""``/health``: is the ledger serving, and how far is its log."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from faultledger.http.context import Context
from faultledger.version import version


def router(context: Context) -> APIRouter:
    api = APIRouter(tags=["system"])

    @api.get("/health", summary="Liveness and the head of the log (no token needed)")
    def health() -> dict[str, Any]:
        ledger = context.ledger
        return {"status": "ok", "version": version(), "last_seq": ledger.last_seq,
                "read_only": context.read_only, "stream_clients": context.hub.clients}

    return api
