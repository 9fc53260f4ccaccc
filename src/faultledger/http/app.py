"""The FastAPI application over one open ``FaultLedger`` (SPEC §10, docs/http.md).

The adapter only translates: parameters to service calls, results and errors to JSON. Every
rule lives in the service and domain layers.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware
from fastapi_offline import FastAPIOffline

from faultledger.domain.shifts import ShiftCalendar
from faultledger.http import errors, medkit
from faultledger.http.auth import Authorizer, BodyLimit, Guarded
from faultledger.http.context import Context
from faultledger.http.heavy import HeavyReads
from faultledger.http.protection import AllowedHosts, BrowserGuard
from faultledger.http.stream import StreamHub
from faultledger.service.config import HttpSettings
from faultledger.service.fleet import Fleet
from faultledger.service.ledger import FaultLedger
from faultledger.service.tokens import TokenBook, TokenWatcher
from faultledger.version import version

DESCRIPTION = (
    "Fault manager HTTP API: ros2_medkit gateway fault endpoints (a medkit client works "
    "unchanged), plus the audit history, time travel, per-shift statistics, reports for "
    "sources without ROS, a resumable event stream and Prometheus metrics."
)

DOCS_URL = "/docs"
DOCS_ASSETS = "/static-offline-docs"
"""Where Swagger UI's script, style sheet and icon are served (fastapi-offline's copies)."""


def create_app(ledger: FaultLedger, settings: HttpSettings, calendar: ShiftCalendar,
               tokens: TokenBook, *, hosts: AllowedHosts, read_only: bool = False,
               loopback: bool = True,
               fleet_labels: dict[str, dict[str, str]] | None = None) -> FastAPI:
    """``tokens`` are those in force at start; while the app runs a ``TokenWatcher`` follows
    the token file. ``loopback``: the server listens on loopback only, so it is open (every
    request anonymous) whenever no token is configured. ``hosts``: the Host values answered
    (protection.py)."""
    hub = StreamHub(ledger, medkit.stream_data, settings.stream_buffer)
    authorizer = Authorizer(tokens, open_without_tokens=loopback)
    heavy = HeavyReads(settings.heavy_reads, settings.heavy_queue, settings.heavy_wait_sec)
    context = Context(ledger, settings, calendar, authorizer, hub, read_only, heavy,
                      fleet=Fleet(ledger), fleet_labels=fleet_labels or {})
    watcher = TokenWatcher(settings, authorizer.replace)

    @asynccontextmanager
    async def lifespan(_app: FastAPI) -> AsyncIterator[None]:
        hub.start()
        watcher.start()
        try:
            yield
        finally:
            watcher.stop()
            hub.stop()
            heavy.close()
            context.pushes.close()
            context.robot_logs().close()

    # /docs (Swagger UI) from assets this server serves (fastapi-offline), not FastAPI's
    # CDN: a robot has no internet. No /redoc: ReDoc's page fetches Redocly's logo from a CDN.
    app = FastAPIOffline(title="faultledger", version=version(), description=DESCRIPTION,
                         lifespan=lifespan, static_url=DOCS_ASSETS, docs_url=DOCS_URL,
                         redoc_url=None)
    app.state.context = context
    errors.install(app)
    from faultledger.http.routes import register  # the routes import the app's modules
    register(app, context)
    # The API's description needs a reader's token, as the API does (the docs' script and
    # style sheet under DOCS_ASSETS are Swagger UI's own and describe nothing: left open).
    app.add_middleware(Guarded, authorizer=authorizer,
                       paths=frozenset(p for p in (app.openapi_url, DOCS_URL) if p))
    if settings.cors_origins:
        app.add_middleware(CORSMiddleware, allow_origins=settings.cors_origins,
                           allow_methods=["GET", "POST", "DELETE"],
                           allow_headers=["Authorization", "Content-Type", "Last-Event-ID"])
    app.add_middleware(BodyLimit, limit=settings.max_body_bytes)
    # Outermost: a request for another host name (DNS rebinding) or a change from another
    # origin is refused before anything else reads it; every answer gets the page headers.
    app.add_middleware(BrowserGuard, hosts=hosts, cors_origins=settings.cors_origins)
    return app
