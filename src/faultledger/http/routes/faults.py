"""The ros2_medkit gateway's fault routes (docs/http.md, "medkit mapping"), plus a global
single-fault route the gateway lacks and a stream that resumes from the log."""

from __future__ import annotations

import asyncio
import json
import logging
import threading
import time
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Header, Path, Query, Request, Response
from sse_starlette import EventSourceResponse, ServerSentEvent
from sse_starlette.sse import SendTimeoutError
from starlette.types import Message, Receive, Scope, Send

from faultledger.domain.attention import SHELVED_VIEWS, in_view
from faultledger.domain.fault import Fault
from faultledger.domain.fleet import robot_id_error
from faultledger.domain.types import FaultStatus
from faultledger.domain.validation import MAX_INTEGER, shown
from faultledger.errors import InvalidInputError, Reason
from faultledger.http import medkit
from faultledger.http.context import Context
from faultledger.http.errors import ApiError
from faultledger.http.stream import StreamHub
from faultledger.service.times import SEQ_NUMBER
from faultledger.service.tokens import Permission, Principal

log = logging.getLogger(__name__)

KEEPALIVE_SEC = 30
"""A ``:keepalive`` comment after this long without events, as the gateway does."""
SEND_TIMEOUT_SEC = 30
"""A stream whose send (events or keep-alive) blocks this long is ended: the client stopped
reading."""
ENTITY_TYPES = ("apps", "components", "areas", "functions")
StatusQuery = Annotated[str | None, Query(
    description="pending, confirmed, cleared (CLEARED+HEALED+PREPASSED), healed "
    "(HEALED+PREPASSED) or all; none: PREFAILED and CONFIRMED")]


def statuses(status: str | None) -> tuple[FaultStatus, ...]:
    if status is None:
        return medkit.DEFAULT_STATUSES
    found = medkit.STATUS_GROUPS.get(status)
    if found is None:
        raise ApiError(Reason.INVALID, "Invalid status parameter value",
                       parameters={"allowed_values": medkit.ALLOWED_STATUS_VALUES,
                                   "parameter": "status", "value": status})
    return found


ShelvedQuery = Annotated[str, Query(
    description="show (medkit's list: every fault, a shelved one marked with `shelved`), "
    "hide (the operator's view: shelved faults left out) or only")]
RobotQuery = Annotated[str | None, Query(
    description="a robot's faults as this fleet central holds its log(s); each item adds "
    "robot_id and ledger_id")]


def robot_faults(context: Context, robot: str, wanted: tuple[FaultStatus, ...]) -> Response:
    """The list of a robot's log(s) at a fleet central, each item naming its log (a robot
    whose database was replaced has two). A robot the central holds nothing of is 404 naming
    the robots it does hold, so a mistyped name is seen at once rather than as no faults."""
    problem = robot_id_error(robot)
    if problem is not None:
        raise ApiError(Reason.INVALID, f"robot: {problem}", parameters={"parameter": "robot"})
    try:  # the robot's name is valid, so the only refusal left is a robot not held
        held = context.robot_logs().faults(robot, [status.value for status in wanted])
    except InvalidInputError as error:
        raise ApiError(Reason.NOT_FOUND, str(error), parameters={"robot": robot}) from None
    # Each log's faults by fault_code (as the central's own list), the logs oldest first.
    answer = medkit.fault_list([item.fault for item in held])
    for entry, item in zip(answer["items"], held, strict=True):
        entry["robot_id"], entry["ledger_id"] = item.robot_id, item.ledger_id
    return Response(json.dumps(answer, separators=(",", ":")).encode(),
                    media_type="application/json", headers={"Cache-Control": "no-cache"})


def writable(context: Context) -> None:
    if context.read_only:
        raise ApiError(Reason.UNAVAILABLE, "this server is read-only (a follower); clear and "
                       "report through the fault manager that writes the database")


def not_found(code: str) -> ApiError:
    return ApiError(Reason.NOT_FOUND, f"Fault not found: {code}",
                    parameters={"fault_code": code})


def last_event_id(value: str | None) -> int | None:
    """The seq a client resumes after: ASCII digits that fit 64 bits. ``str.isdigit`` alone
    would pass ``²`` or ``٣`` (int() refuses the one, reads the other as 3)."""
    if value is None or value.strip() == "":
        return None
    text = value.strip()
    if not SEQ_NUMBER.fullmatch(text) or int(text) > MAX_INTEGER:
        raise ApiError(Reason.INVALID, f"Last-Event-ID must be the seq of an event received "
                       f"(digits), got {shown(value)}")
    return int(text)


class ListCache:
    """The encoded list per status group, valid while the log's head seq stays the same:
    every change of a fault is a record, so an unchanged seq means unchanged faults. A busy
    dashboard or monitoring poll then costs a dictionary look-up, not 10,000 encodings."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._seq = -1
        self._content: dict[tuple[tuple[FaultStatus, ...], str], bytes] = {}

    def get(self, seq: int, wanted: tuple[tuple[FaultStatus, ...], str]) -> bytes | None:
        with self._lock:
            return self._content.get(wanted) if seq == self._seq else None

    def put(self, seq: int, wanted: tuple[tuple[FaultStatus, ...], str], content: bytes
            ) -> None:
        with self._lock:
            if seq != self._seq:
                self._seq, self._content = seq, {}
            self._content[wanted] = content


def _keepalive() -> ServerSentEvent:
    return ServerSentEvent(comment="keepalive")


class _Stream(EventSourceResponse):
    """The SSE response of one client. A client that stopped reading is a dropped client,
    like one that fell behind the hub's buffer: counted in
    ``faultledger_stream_dropped_clients_total`` and logged in one line, never a traceback.
    It is ended either here, by a send blocked for ``SEND_TIMEOUT_SEC`` (sse-starlette's
    SendTimeoutError), or under the response by the server's connection layer closing a
    connection that reads nothing (then the stream sees a disconnect while a send to it is
    blocked, or right after one was blocked for ``BLOCKED_SEC`` or more)."""

    BLOCKED_SEC = 1.0

    def __init__(self, hub: StreamHub, after: int | None) -> None:
        super().__init__(hub.events(after), ping=KEEPALIVE_SEC, ping_message_factory=_keepalive,
                         send_timeout=SEND_TIMEOUT_SEC, headers={"X-Accel-Buffering": "no"})
        self._hub = hub
        self._sending_since: float | None = None
        self._last_send_blocked = False
        self._cut_while_blocked = False

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        loop = asyncio.get_running_loop()

        async def timed_send(message: Message) -> None:
            self._sending_since = started = loop.time()
            try:
                await send(message)
            finally:
                self._sending_since = None
                self._last_send_blocked = loop.time() - started >= self.BLOCKED_SEC

        async def watched_receive() -> Message:
            message = await receive()
            if message["type"] == "http.disconnect" and (
                    self._sending_since is not None or self._last_send_blocked):
                self._cut_while_blocked = True
            return message

        client = "{}:{}".format(*(scope.get("client") or ("?", 0)))
        try:
            await super().__call__(scope, watched_receive, timed_send)
        except SendTimeoutError:
            self._hub.dropped_clients += 1
            log.warning("event stream of %s ended: a send was blocked for %d s (the client "
                        "stopped reading); it resumes with Last-Event-ID", client,
                        SEND_TIMEOUT_SEC)
            return
        if self._cut_while_blocked:
            self._hub.dropped_clients += 1
            log.warning("event stream of %s ended while a send to it was blocked (the client "
                        "stopped reading); it resumes with Last-Event-ID", client)


def router(context: Context) -> APIRouter:
    api = APIRouter(prefix="/api/v1", tags=["faults (ros2_medkit gateway)"])
    ledger = context.ledger
    read = Depends(context.auth.need(Permission.READ))
    clear_permission = Depends(context.auth.need(Permission.CLEAR))

    @api.get("/faults/stream", summary="Live fault events (SSE); id = log seq, resumable with "
             "Last-Event-ID", response_class=EventSourceResponse)
    async def stream(request: Request, _: Principal = read,
                     last_event: Annotated[str | None, Header(alias="Last-Event-ID")] = None,
                     ) -> EventSourceResponse:
        after = last_event_id(last_event or request.query_params.get("last_event_id"))
        return _Stream(context.hub, after)

    cache = ListCache()

    @api.get("/faults", summary="Faults by medkit status group",
             response_model=None, responses={200: {"content": {"application/json": {}}}})
    def list_faults(request: Request, status: StatusQuery = None, include_muted: bool = False,
                    include_clusters: bool = False, robot: RobotQuery = None,
                    shelved: ShelvedQuery = "show", _: Principal = read) -> Response:
        wanted = statuses(status)
        if shelved not in SHELVED_VIEWS:
            raise ApiError(Reason.INVALID, "Invalid shelved parameter value",
                           parameters={"allowed_values": ", ".join(SHELVED_VIEWS),
                                       "parameter": "shelved", "value": shelved})
        if robot is not None:
            return robot_faults(context, robot, wanted)
        seq = ledger.last_seq
        view = "" if shelved == "show" else f"-{shelved}"
        etag = f'"{seq}-{status or "default"}{view}"'
        if request.headers.get("if-none-match") == etag:
            return Response(status_code=304, headers={"ETag": etag})
        content = cache.get(seq, (wanted, shelved))
        if content is None:
            chosen = [f for f in ledger.all_faults() if f.status in wanted]
            chosen = in_view(chosen, time.time_ns(), shelved)  # medkit's order: by code
            content = json.dumps(medkit.fault_list(chosen), separators=(",", ":")).encode()
            cache.put(seq, (wanted, shelved), content)
        return Response(content, media_type="application/json", headers={"ETag": etag})

    @api.get("/faults/{fault_code}", summary="One fault in any status (SOVD shape)")
    def get_fault(fault_code: str, _: Principal = read) -> dict[str, Any]:
        found = ledger.lookup_fault(fault_code)
        if found.fault is None:
            if found.reason == Reason.NOT_FOUND:
                raise not_found(fault_code)
            raise ApiError(found.reason or Reason.INVALID, found.message)
        return medkit.fault_detail(found.fault)

    @api.delete("/faults/{fault_code}", status_code=204, summary="Clear one fault")
    def clear_fault(fault_code: str, reason: str = "",
                    principal: Principal = clear_permission) -> Response:
        writable(context)
        clear_one(context, fault_code, principal, reason)
        return Response(status_code=204)

    @api.delete("/faults", status_code=204, summary="Clear every fault of a status group")
    def clear_faults(status: StatusQuery = None, reason: str = "",
                     principal: Principal = clear_permission) -> Response:
        writable(context)
        clear_group(context, ledger.all_faults(), statuses(status), principal, reason)
        return Response(status_code=204, headers={"X-Medkit-Local-Only": "true"})

    for kind in ENTITY_TYPES:
        _entity_routes(api, context, kind, read, clear_permission)
    return api


def clear_one(context: Context, fault_code: str, principal: Principal, reason: str) -> None:
    """A clear recorded with the token's name as actor; an unknown fault is 404."""
    result = context.ledger.clear(fault_code, actor=principal.name, reason=reason)
    if not result.success:
        if result.reason == Reason.NOT_FOUND:
            raise not_found(fault_code)
        raise ApiError(result.reason, result.message)


def clear_group(context: Context, faults: list[Fault], wanted: tuple[FaultStatus, ...],
                principal: Principal, reason: str) -> None:
    """Clear each of ``faults`` in a ``wanted`` status (a CLEARED one is left as it is)."""
    for fault in faults:
        if fault.status in wanted and fault.status is not FaultStatus.CLEARED:
            result = context.ledger.clear(fault.fault_code, actor=principal.name, reason=reason)
            if not result.success and result.reason != Reason.NOT_FOUND:
                raise ApiError(result.reason, result.message)


def _entity_routes(api: APIRouter, context: Context, kind: str, read: Any,
                   clear_permission: Any) -> None:
    """``/{apps,components,areas,functions}/{id}/faults[/{code}]``: the faults an entity
    reported (a reporting source is the id or ends in ``/id``, as ``list_faults_for_entity``).
    An entity no fault was ever reported by is unknown: 404 ``entity-not-found``, as the
    gateway answers for an entity it has not discovered."""
    ledger = context.ledger
    singular = kind.removesuffix("s")
    id_field = f"{singular}_id"  # the gateway's path parameter and error parameter names
    entity = Path(alias=id_field, description=f"The {singular}: a fault belongs to it when "
                  "one of its reporting sources is the id or ends in /id")
    title = singular.capitalize()

    def in_scope(entity_id: str) -> list[Fault]:
        found = ledger.lookup_entity(entity_id)
        if not found.success:
            raise ApiError(found.reason or Reason.INVALID, found.message,
                           parameters={"entity_id": entity_id})
        if not found.faults:
            raise ApiError(Reason.NOT_FOUND, "Entity not found", error_code="entity-not-found",
                           parameters={"details": f"no fault was ever reported by a source "
                                       f"named {entity_id!r} or ending in '/{entity_id}'",
                                       "entity_id": entity_id})
        return found.faults

    def fault_of(entity_id: str, fault_code: str) -> Fault:
        scope = in_scope(entity_id)
        found = ledger.lookup_fault(fault_code)
        if found.fault is None and found.reason != Reason.NOT_FOUND:
            raise ApiError(found.reason or Reason.INVALID, found.message)
        for fault in scope:
            if fault.fault_code == fault_code:
                return fault
        raise ApiError(Reason.NOT_FOUND, f"Fault not found: {fault_code}",
                       parameters={id_field: entity_id, "fault_code": fault_code})

    @api.get(f"/{kind}/{{{id_field}}}/faults", summary=f"Faults of one of the {kind}",
             operation_id=f"list{title}Faults")
    def entity_faults(entity_id: str = entity, status: StatusQuery = None,
                      _: Principal = read) -> dict[str, Any]:
        wanted = statuses(status)
        answer = medkit.fault_list([f for f in in_scope(entity_id) if f.status in wanted])
        answer["x-medkit"]["entity_id"] = entity_id
        return answer

    @api.get(f"/{kind}/{{{id_field}}}/faults/{{fault_code}}",
             summary=f"One fault of one of the {kind}", operation_id=f"get{title}Fault")
    def entity_fault(fault_code: str, entity_id: str = entity, _: Principal = read
                     ) -> dict[str, Any]:
        return medkit.fault_detail(fault_of(entity_id, fault_code))

    @api.delete(f"/{kind}/{{{id_field}}}/faults/{{fault_code}}", status_code=204,
                summary=f"Clear one fault of one of the {kind}",
                operation_id=f"clear{title}Fault")
    def clear_entity_fault(fault_code: str, entity_id: str = entity, reason: str = "",
                           principal: Principal = clear_permission) -> Response:
        writable(context)
        clear_one(context, fault_of(entity_id, fault_code).fault_code, principal, reason)
        return Response(status_code=204)

    @api.delete(f"/{kind}/{{{id_field}}}/faults", status_code=204,
                summary=f"Clear the faults of one of the {kind} (default: PREFAILED and "
                "CONFIRMED, as the gateway)", operation_id=f"clearAll{title}Faults")
    def clear_entity_faults(entity_id: str = entity, status: StatusQuery = None,
                            reason: str = "", principal: Principal = clear_permission
                            ) -> Response:
        writable(context)
        clear_group(context, in_scope(entity_id), statuses(status), principal, reason)
        return Response(status_code=204)
