"""The JSON each receiver type gets for one alert (docs/alerts.md, "Receivers"): a plain
webhook, a Slack incoming webhook, PagerDuty's Events API v2."""

from __future__ import annotations

from typing import Any

from faultledger.domain.alerts import FLOOD, PAGERDUTY_ACTIONS, STALE, SYNC_LAG, Alert
from faultledger.domain.clock import NS_PER_SECOND, from_ns

PAGERDUTY_SEVERITY = {0: "info", 1: "warning", 2: "error", 3: "critical"}
MAX_SUMMARY = 1024
"""PagerDuty cuts a summary after 1,024 characters; we cut first, visibly."""


def webhook(alert: Alert) -> dict[str, Any]:
    """Every field a receiver needs to act and to deduplicate; ``details`` only for the
    derived events (flood, stale, sync_lag)."""
    body: dict[str, Any] = {
        "event": alert.event, "fault_code": alert.fault_code,
        "severity": alert.severity_text, "status": alert.status, "seq": alert.seq,
        "ledger_id": alert.ledger_id, "robot_id": alert.robot_id,
        "occurred_at": alert.occurred_at, "idempotency_key": alert.key,
    }
    if alert.details:
        body["details"] = alert.details
    return body


def slack(alert: Alert) -> dict[str, Any]:
    """An incoming webhook's message: one line."""
    return {"text": _escape(headline(alert))}


def pagerduty(alert: Alert, routing_key: str) -> dict[str, Any]:
    """trigger / acknowledge / resolve of the incident ``alert.incident`` (the dedup_key:
    ``ledger_id:code:episode`` for a fault's episode, so a new episode is a new incident)."""
    summary = headline(alert)
    if alert.description:
        summary += f": {alert.description}"
    if len(summary) > MAX_SUMMARY:
        summary = summary[:MAX_SUMMARY - 1] + "…"
    details: dict[str, Any] = {
        "event": alert.event, "fault_code": alert.fault_code, "status": alert.status,
        "episode": alert.episode, "seq": alert.seq, "ledger_id": alert.ledger_id,
        "idempotency_key": alert.key, **alert.details}
    return {
        "routing_key": routing_key,
        "event_action": PAGERDUTY_ACTIONS[alert.event],
        "dedup_key": alert.incident,
        "payload": {
            "summary": summary,
            "source": alert.robot_id,
            "severity": PAGERDUTY_SEVERITY.get(alert.severity if alert.severity is not None
                                               else 2, "error"),
            "timestamp": alert.occurred_at,
            "custom_details": {k: v for k, v in details.items() if v is not None},
        },
    }


def headline(alert: Alert) -> str:
    """``fault_confirmed: HW_MOTOR CRITICAL CONFIRMED on robot-a`` and the like."""
    robot = f"on {alert.robot_id}"
    if alert.event == FLOOD:
        start = from_ns(int(alert.details["window_start_ns"])).strftime("%Y-%m-%d %H:%M")
        return (f"flood: more than {alert.details['more_than']} confirmations in the 10 "
                f"minutes from {start} UTC {robot} (the {alert.details['confirmations']}th: "
                f"{alert.fault_code} {alert.severity_text})")
    if alert.event == SYNC_LAG:
        return (f"sync_lag: the central holds {alert.robot_id}'s log complete only up to "
                f"{alert.details['complete_until']} (lag above "
                f"{alert.details['threshold_seconds']:g} s, held up to seq {alert.seq})")
    text = (f"{alert.event}: {alert.fault_code} {alert.severity_text} {alert.status} "
            f"{robot}")
    if alert.event == STALE:
        hours = int(alert.details["confirmed_for_ns"]) / NS_PER_SECOND / 3600
        text += f" (CONFIRMED since {alert.occurred_at}, {hours:.0f} h)"
    return text


def _escape(text: str) -> str:
    """Slack reads & < > as markup."""
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
