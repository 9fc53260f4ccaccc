"""The API's routes, one module per concern; ``register`` mounts them all."""

from __future__ import annotations

from fastapi import FastAPI

from faultledger.http.context import Context


def register(app: FastAPI, context: Context) -> None:
    from faultledger.http import dashboard
    from faultledger.http.routes import (
        alerts,
        audit,
        faults,
        fleet,
        metrics,
        operator,
        reports,
        stats,
        system,
    )

    for module in (faults, operator, reports, audit, stats, metrics, system, fleet, alerts,
                   dashboard):
        app.include_router(module.router(context))
