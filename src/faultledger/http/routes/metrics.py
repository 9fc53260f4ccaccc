"""``GET /metrics``: Prometheus text format (needs the read permission)."""

from __future__ import annotations

from fastapi import APIRouter, Depends, Response
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest

from faultledger.http.context import Context
from faultledger.http.metrics import registry
from faultledger.service.tokens import Permission, Principal


def router(context: Context) -> APIRouter:
    api = APIRouter(tags=["system"])
    read = Depends(context.auth.need(Permission.READ))
    metrics = registry(context)

    @api.get("/metrics", summary="Prometheus metrics (text format)",
             response_class=Response)
    def scrape(_: Principal = read) -> Response:
        return Response(generate_latest(metrics), media_type=CONTENT_TYPE_LATEST)

    return api
