"""``GET /api/v1/alerts``: the alert rules' cursors and leases and their deliveries, newest
first (docs/alerts.md, "Seeing the deliveries"); the read permission."""

from __future__ import annotations

import time
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Query

from faultledger.http.context import Context
from faultledger.service import alerts
from faultledger.service.tokens import Permission, Principal


def router(context: Context) -> APIRouter:
    api = APIRouter(prefix="/api/v1", tags=["alerts"])
    read = Depends(context.auth.need(Permission.READ))

    @api.get("/alerts", summary="Alert deliveries (newest first) and each rule's state")
    def deliveries(
        rule: str | None = None,
        state: Annotated[list[str] | None, Query(
            description="pending, retrying, delivered or failed (repeatable)")] = None,
        limit: Annotated[int, Query(ge=1, le=alerts.MAX_LISTED)] = 100,
        _: Principal = read,
    ) -> dict[str, Any]:
        found = alerts.deliveries(context.ledger, rule, state or (), limit)
        now = time.time_ns()
        return {"rules": [alerts.rule_dict(r, now) for r in alerts.rule_states(context.ledger)
                          if rule is None or r.rule == rule],
                "deliveries": [alerts.delivery_dict(d, now) for d in found]}

    return api
