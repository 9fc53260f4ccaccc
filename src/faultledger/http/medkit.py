"""ros2_medkit gateway JSON shapes for faults, field for field (docs/http.md, "medkit mapping").

Checked against the gateway's code (fault_msg_conversions.cpp ``fault_to_json``,
fault_handlers.cpp ``build_sovd_fault_response``, sse_fault_handler.cpp): list items and stream
events carry times as float seconds since the epoch; the single-fault answer carries the SOVD
status object with "0"/"1" strings and ISO 8601 times in ``environment_data``. Keys are sorted,
as the gateway's JSON library writes them; optional keys are left out, never null.
"""

from __future__ import annotations

from typing import Any

from faultledger.domain.clock import NS_PER_SECOND, from_ns
from faultledger.domain.fault import Fault
from faultledger.domain.notifications import Notification
from faultledger.domain.types import FaultStatus

STATUS_GROUPS: dict[str, tuple[FaultStatus, ...]] = {
    "pending": (FaultStatus.PREFAILED,),
    "confirmed": (FaultStatus.CONFIRMED,),
    "cleared": (FaultStatus.CLEARED, FaultStatus.HEALED, FaultStatus.PREPASSED),
    "healed": (FaultStatus.HEALED, FaultStatus.PREPASSED),
    "all": tuple(FaultStatus),
}
"""``?status=`` values and the statuses each selects; none given: PREFAILED and CONFIRMED."""
DEFAULT_STATUSES = (FaultStatus.PREFAILED, FaultStatus.CONFIRMED)
ALLOWED_STATUS_VALUES = ", ".join(STATUS_GROUPS)

SEVERITY_LABELS = {0: "INFO", 1: "WARN", 2: "ERROR", 3: "CRITICAL"}

_SOVD_STATUS: dict[FaultStatus, tuple[str, str, str, str]] = {
    # status: aggregatedStatus, testFailed, confirmedDTC, pendingDTC
    FaultStatus.CONFIRMED: ("active", "1", "1", "0"),
    FaultStatus.PREFAILED: ("passive", "1", "0", "1"),
    FaultStatus.PREPASSED: ("passive", "0", "0", "1"),
    FaultStatus.HEALED: ("cleared", "0", "0", "0"),
    FaultStatus.CLEARED: ("cleared", "0", "0", "0"),
}


def severity_label(severity: int) -> str:
    return SEVERITY_LABELS.get(severity, "UNKNOWN")


def seconds(ns: int) -> float:
    return ns / NS_PER_SECOND


def iso_ms(ns: int) -> str:
    """``2026-02-04T10:30:00.123Z``, as the gateway's ``format_timestamp_ns``."""
    moment = from_ns(ns)
    return moment.strftime("%Y-%m-%dT%H:%M:%S.") + f"{moment.microsecond // 1000:03d}Z"


def fault_item(fault: Fault) -> dict[str, Any]:
    """One fault in a list or a stream event (the gateway's ``fault_to_json``)."""
    item: dict[str, Any] = {
        "description": fault.description,
        "fault_code": fault.fault_code,
        "first_occurred": seconds(fault.first_occurred_ns),
        "last_occurred": seconds(fault.last_occurred_ns),
        "occurrence_count": fault.occurrence_count,
        "reporting_sources": list(fault.reporting_sources),
        "severity": fault.severity,
        "severity_label": severity_label(fault.severity),
        "status": fault.status.value,
    }
    if fault.last_passed_ns:
        item["last_passed"] = seconds(fault.last_passed_ns)
    item.update(attention(fault))
    return dict(sorted(item.items()))


def attention(fault: Fault) -> dict[str, Any]:
    """Ours, beyond medkit: who acknowledged the current episode and the shelving in force,
    each only when there is one (so a fault nobody touched has the gateway's exact keys)."""
    found: dict[str, Any] = {}
    ack = fault.acknowledged
    if ack is not None:
        found["acknowledged"] = {"by": ack.actor, "at": seconds(ack.at_ns), "note": ack.note,
                                 "seq": ack.seq}
    shelf = fault.shelved
    if shelf is not None:
        found["shelved"] = {"by": shelf.actor, "at": seconds(shelf.at_ns),
                            "until": seconds(shelf.until_ns), "reason": shelf.reason,
                            "seq": shelf.seq}
    return found


def fault_list(faults: list[Fault]) -> dict[str, Any]:
    """``{"items", "x-medkit"}``: ``count`` is what the gateway's code emits, ``total_count``
    what its documentation shows; both are the number of items (nothing is paged)."""
    return {"items": [fault_item(fault) for fault in faults],
            "x-medkit": {"cluster_count": 0, "count": len(faults), "muted_count": 0,
                         "total_count": len(faults)}}


def fault_detail(fault: Fault) -> dict[str, Any]:
    """The single-fault answer: SOVD item and status object, environment data, x-medkit."""
    aggregated, failed, confirmed, pending = _SOVD_STATUS[fault.status]
    item: dict[str, Any] = {
        "code": fault.fault_code,
        "severity": fault.severity,
        "status": {"aggregatedStatus": aggregated, "confirmedDTC": confirmed,
                   "pendingDTC": pending, "testFailed": failed},
    }
    if fault.description:
        item["fault_name"] = fault.description
    extra: dict[str, Any] = {"occurrence_count": fault.occurrence_count,
                             "severity_label": severity_label(fault.severity),
                             "status_raw": fault.status.value,
                             # beyond medkit (x- keys are for extensions):
                             "first_occurred": seconds(fault.first_occurred_ns),
                             "last_occurred": seconds(fault.last_occurred_ns),
                             "debounce_counter": fault.debounce_counter,
                             # the episodes, from the log (medkit's first_occurred resets):
                             "episode": fault.episode,
                             "episode_started": seconds(fault.first_occurred_ns),
                             "first_occurred_ever": seconds(fault.first_ever_ns
                                                            or fault.first_occurred_ns),
                             "occurrences_in_episode": fault.episode_failures,
                             "occurrences_total": fault.total_failures,
                             **attention(fault)}
    if fault.reporting_sources:
        extra["reporting_sources"] = list(fault.reporting_sources)
    if fault.last_passed_ns:
        extra["last_passed"] = seconds(fault.last_passed_ns)
    return {
        "environment_data": {
            "extended_data_records": {"first_occurrence": iso_ms(fault.first_occurred_ns),
                                      "last_occurrence": iso_ms(fault.last_occurred_ns)},
            "snapshots": [],
        },
        "item": dict(sorted(item.items())),
        "x-medkit": dict(sorted(extra.items())),
    }


def stream_data(notification: Notification) -> dict[str, Any]:
    """The ``data:`` of one stream event (the gateway's SSE handler); the event's ``id:`` is
    the log seq of the record that caused it."""
    return {"event_type": notification.event_type.value,
            "fault": fault_item(notification.fault),
            "timestamp": seconds(notification.timestamp_ns)}
