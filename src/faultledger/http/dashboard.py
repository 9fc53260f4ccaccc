"""The web dashboard: one page at ``/`` and its assets at ``/static/…``, all served by this
server (robots have no internet). The page talks to the same API as any client (docs/http.md,
"Dashboard"); it needs no token itself and asks for one when the API answers 401."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from fastapi import APIRouter
from fastapi.responses import FileResponse, HTMLResponse
from jinja2 import Environment, PackageLoader, StrictUndefined, select_autoescape

from faultledger.domain.validation import shown
from faultledger.errors import Reason
from faultledger.http.context import Context
from faultledger.http.errors import ApiError
from faultledger.version import version

STATIC = Path(__file__).resolve().parent / "static"
MEDIA = {".js": "text/javascript", ".css": "text/css", ".svg": "image/svg+xml"}


@lru_cache(maxsize=1)
def _environment() -> Environment:
    return Environment(loader=PackageLoader("faultledger", "templates"),
                       autoescape=select_autoescape(default=True), undefined=StrictUndefined)


def router(context: Context) -> APIRouter:
    api = APIRouter(tags=["dashboard"], include_in_schema=False)
    # The page shows every time in the shift calendar's zone (as the reports do) and names
    # the configured e-stop globs; both are fixed for the server's life.
    page = _environment().get_template("dashboard.html").render(
        version=version(), read_only=context.read_only, zone=context.calendar.timezone,
        estop_codes=list(context.ledger.estop_codes))

    @api.get("/", response_class=HTMLResponse)
    def dashboard() -> HTMLResponse:
        return HTMLResponse(page, headers={"Cache-Control": "no-cache"})

    # The assets are the files shipped in static/, named once at start: a request's name is
    # looked up among them, never handed to the file system (a 5,000-character name is a
    # plain 404, not "File name too long").
    assets = {path.name: path for path in STATIC.iterdir()
              if path.is_file() and path.suffix in MEDIA and not path.name.startswith(".")}

    @api.get("/static/{name}")
    def asset(name: str) -> FileResponse:
        path = assets.get(name)
        if path is None:
            raise ApiError(Reason.NOT_FOUND, f"no such file: {shown(name)}")
        return FileResponse(path, media_type=MEDIA[path.suffix],
                            headers={"Cache-Control": "no-cache"})

    return api
