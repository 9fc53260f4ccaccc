"""Prometheus metrics, computed at scrape time from the ledger and the stream hub (docs/http.md,
"Metrics"). A registry of our own per app: nothing global, nothing counted twice."""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Iterator

from prometheus_client import CollectorRegistry
from prometheus_client.core import (
    CounterMetricFamily,
    GaugeMetricFamily,
    HistogramMetricFamily,
    Metric,
)
from prometheus_client.registry import Collector

from faultledger.domain.clock import NS_PER_SECOND
from faultledger.domain.types import FaultStatus
from faultledger.http.context import Context
from faultledger.http.medkit import severity_label
from faultledger.service import alerts
from faultledger.service.fleet import Fleet
from faultledger.service.ledger import FaultLedger
from faultledger.service.telemetry import COMMIT_BUCKETS


class LedgerCollector(Collector):
    def __init__(self, context: Context) -> None:
        self._context = context

    def collect(self) -> Iterator[Metric]:
        ledger = self._context.ledger
        faults = GaugeMetricFamily("faultledger_faults", "Faults by status and severity",
                                   labels=["status", "severity"])
        counts = Counter((f.status.value, severity_label(f.severity))
                         for f in ledger.all_faults())
        for status in FaultStatus:
            for severity in ("INFO", "WARN", "ERROR", "CRITICAL"):
                faults.add_metric([status.value, severity], counts.get((status.value, severity),
                                                                       0))
        yield faults
        snapshot = ledger.telemetry
        reports = CounterMetricFamily("faultledger_reports", "Reports this process recorded, "
                                      "by event type", labels=["event_type"])
        for event_type in ("FAILED", "PASSED"):
            reports.add_metric([event_type], snapshot.reports.get(event_type, 0))
        yield reports
        records = CounterMetricFamily("faultledger_records", "Log records this process "
                                      "appended, by kind", labels=["kind"])
        for kind, count in sorted(snapshot.records.items()):
            records.add_metric([kind], count)
        yield records
        cumulative, buckets = 0, []
        for bound, count in zip((*map(str, COMMIT_BUCKETS), "+Inf"), snapshot.commit_buckets,
                                strict=True):
            cumulative += count
            buckets.append((bound, cumulative))
        latency = HistogramMetricFamily("faultledger_commit_seconds", "Group commit latency "
                                        "of this process's writer (append to durable)")
        latency.add_metric([], buckets, snapshot.commit_seconds_sum)
        yield latency
        yield GaugeMetricFamily("faultledger_last_seq", "Seq of the newest record this "
                                "process has applied", value=ledger.last_seq)
        hub = self._context.hub
        yield GaugeMetricFamily("faultledger_stream_clients", "Connected event stream "
                                "clients", value=hub.clients)
        dropped = CounterMetricFamily("faultledger_stream_dropped_clients", "Stream clients "
                                      "disconnected for falling behind the buffer")
        dropped.add_metric([], hub.dropped_clients)
        yield dropped
        yield from _fleet(self._context.robot_logs())
        yield from _alerts(ledger)


def _fleet(robot_logs: Fleet) -> Iterator[Metric]:
    """Per robot log a central holds (docs/fleet.md, "Lag"); nothing on a robot."""
    labels = ["robot_id", "ledger_id"]
    seconds = GaugeMetricFamily("faultledger_fleet_lag_seconds", "How far behind the central "
                                "is with a robot's log: now minus the time up to which it "
                                "holds all of it", labels=labels)
    records = GaugeMetricFamily("faultledger_fleet_lag_records", "Records a robot had and the "
                                "central lacked at the robot's last contact", labels=labels)
    held = GaugeMetricFamily("faultledger_fleet_records", "Records of a robot's log the "
                             "central holds", labels=labels)
    unprojected = GaugeMetricFamily("faultledger_fleet_unprojected_records", "Records of a "
                                    "robot's log the central stored but has not yet projected "
                                    "(docs/fleet.md)", labels=labels)
    behind = robot_logs.behind()
    for chain in robot_logs.robots():
        key = [chain.robot_id, chain.ledger_id]
        seconds.add_metric(key, chain.lag_seconds)
        records.add_metric(key, chain.lag_records)
        held.add_metric(key, chain.records)
        unprojected.add_metric(key, behind.get(chain.ledger_id, 0))
    yield from (seconds, records, held, unprojected)


def _alerts(ledger: FaultLedger) -> Iterator[Metric]:
    """Per alert rule that has run on this database (docs/alerts.md); nothing without one."""
    deliveries = GaugeMetricFamily("faultledger_alert_deliveries", "Alert deliveries in the "
                                   "outbox by rule and state (pending, retrying, delivered, "
                                   "failed)", labels=["rule", "state"])
    oldest = GaugeMetricFamily("faultledger_alert_oldest_undelivered_seconds", "How long the "
                               "oldest undelivered alert of a rule has been due (0: none)",
                               labels=["rule"])
    unscanned = GaugeMetricFamily("faultledger_alert_unscanned_records", "Log records a "
                                  "rule's scan has not reached yet", labels=["rule"])
    now = time.time_ns()
    head = ledger.last_seq
    for rule in alerts.rule_states(ledger):
        for state, count in rule.counts.items():
            deliveries.add_metric([rule.rule, state], count)
        oldest.add_metric([rule.rule], 0.0 if rule.oldest_undelivered_ns is None
                          else max(0, now - rule.oldest_undelivered_ns) / NS_PER_SECOND)
        unscanned.add_metric([rule.rule], max(0, head - rule.cursor))
    yield from (deliveries, oldest, unscanned)


def registry(context: Context) -> CollectorRegistry:
    found = CollectorRegistry(auto_describe=False)
    found.register(LedgerCollector(context))
    return found
