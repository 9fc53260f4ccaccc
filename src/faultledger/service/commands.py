"""Requests checked into the writer's commands: every field is validated before a request joins
a group commit, so one bad request never fails the commit it would share with valid ones."""

from __future__ import annotations

import time
import uuid

from faultledger.domain import validation
from faultledger.domain.clock import to_ns
from faultledger.domain.events import FaultReported, GoalOutcome, goal_event_id
from faultledger.service.event_ids import new_event_id
from faultledger.service.requests import GoalOutcomeRequest, ReportRequest
from faultledger.service.results import ReportResult
from faultledger.service.writer import RecordGoal, Report


def report_command(request: ReportRequest) -> Report | ReportResult:
    """The writer's command for a valid report, else the rejection naming the problem.

    Every field is checked here, before the report joins a group commit: one bad report must
    never fail the commit it would share with valid ones (the writer isolates one that
    still does, as a last resort).
    """
    if not isinstance(request, ReportRequest):
        return ReportResult(False, f"expected a ReportRequest, got {type(request).__name__}")
    kind = validation.parse_event_type(request.event_type)
    problem = validation.report_error(request.fault_code, request.event_type, request.severity,
                                      request.description, request.source_id)
    event_id = None
    if problem is None and request.event_id is not None:
        event_id = canonical_event_id(request.event_id)
        if event_id is None:
            problem = f"event_id must be a UUID, got {validation.shown(request.event_id)}"
    if problem is None and request.at is not None:
        problem = validation.time_error("at", request.at)
    if problem is not None or kind is None:
        return ReportResult(False, problem or "invalid report")
    occurred_ns = time.time_ns() if request.at is None else to_ns(request.at)
    event = FaultReported(request.fault_code, kind, request.severity, request.description,
                          request.source_id)
    return Report(event, occurred_ns, event_id or new_event_id(), event_id is not None)


def goal_command(request: GoalOutcomeRequest) -> RecordGoal | ReportResult:
    """The writer's command for a valid goal outcome, else the rejection naming the problem
    (checked before it joins a group commit, like a report)."""
    if not isinstance(request, GoalOutcomeRequest):
        return ReportResult(False, f"expected a GoalOutcomeRequest, got {type(request).__name__}")
    problem = validation.goal_outcome_error(request.action, request.goal_id, request.status,
                                            request.server_node)
    if problem is None and request.at is not None:
        problem = validation.time_error("at", request.at)
    if problem is not None:
        return ReportResult(False, problem)
    occurred_ns = time.time_ns() if request.at is None else to_ns(request.at)
    event = GoalOutcome(request.action, request.goal_id, request.status, request.server_node)
    return RecordGoal(event, occurred_ns, goal_event_id(request.action, request.goal_id))


def canonical_event_id(event_id: object) -> str | None:
    """The one spelling of a UUID the log stores and the idempotency check compares: lowercase
    and hyphenated. Every spelling ``uuid.UUID`` reads (upper case, ``{…}``, ``urn:uuid:…``,
    no hyphens) is the same report. None: not a UUID."""
    if not isinstance(event_id, str) or len(event_id) > 64:
        return None
    try:
        return str(uuid.UUID(event_id))
    except ValueError:
        return None
