"""Node-state heartbeats → fault reports: the per-node state machine, without rclpy.

Kept apart from the ROS node so the mapping (codes, edges, heartbeat timeouts) is unit-tested
with explicit monotonic times. The bridge feeds it every ``NodeState`` message with the steady
clock's reading at receipt and calls ``check`` periodically; both return the reports to make.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from faultledger.domain.validation import MAX_DESCRIPTION_LENGTH
from faultledger.ros.bridges.codes import fault_code, upper_snake

# nodemon_msgs/msg/NodeState constants.
STARTING, STOPPING, RUNNING, ERROR, RECOVERING, FATAL, WARNING = range(7)
STATE_NAMES: dict[int, str] = {
    STARTING: "STARTING", STOPPING: "STOPPING", RUNNING: "RUNNING", ERROR: "ERROR",
    RECOVERING: "RECOVERING", FATAL: "FATAL", WARNING: "WARNING",
}

SUFFIX_ERROR = "ERROR"
SUFFIX_FATAL = "FATAL"
SUFFIX_WARNING = "WARNING"
SUFFIX_HEARTBEAT_LOST = "HEARTBEAT_LOST"
CODE_PREFIX = "NODE_"
"""Codes are ``NODE_<NAME>_<SUFFIX>``, ``<NAME>`` the node FQN by ``codes.fault_code``."""


HEARTBEAT_TIMEOUT_SEC = 5.0
"""Default silence after which a node's heartbeat is lost (bridge and ``faultledger nodes``)."""


def heartbeat_lost(state: int | None, last_seen: float, now: float,
                   timeout_sec: float = HEARTBEAT_TIMEOUT_SEC) -> bool:
    """The one timeout rule: silent for longer than ``timeout_sec`` (steady clock, seconds)
    and its last state was not STOPPING (a clean exit is no loss)."""
    return state != STOPPING and now - last_seen > timeout_sec


@dataclass(frozen=True)
class Severities:
    """Severity of each FAILED the bridge reports (0 INFO … 3 CRITICAL)."""

    error: int = 2
    fatal: int = 3
    warning: int = 1
    heartbeat_lost: int = 2


@dataclass(frozen=True)
class Report:
    """One report for the FaultReporter: FAILED (with severity/description) or PASSED."""

    kind: Literal["failed", "passed"]
    code: str
    source_id: str
    severity: int = 0
    description: str = ""


@dataclass
class NodeInfo:
    """What is known of one node: the last sustained state (WARNING is transient and not
    kept here), its last heartbeat on the steady clock and which of its codes are FAILED."""

    nodename: str
    package: str = ""
    nodetype: str = ""
    state: int | None = None
    machine_message: str = ""
    human_message: str = ""
    last_seen: float = 0.0
    lost: bool = False
    raised: list[str] = field(default_factory=list)  # suffixes FAILED since the last PASSED


def describe(human: str, machine: str) -> str:
    """Description of a report: the human message, then the machine message in brackets."""
    text = f"{human} [{machine}]" if human and machine else human or machine
    return text[:MAX_DESCRIPTION_LENGTH]


class BadMessage(ValueError):
    """A NodeState that cannot be mapped (empty node name, unknown state value)."""


class NodeStateMonitor:
    """The edge-triggered mapping of every node seen (SPEC §8 node-state bridge).

    * entry into ERROR / FATAL → FAILED ``NODE_<NAME>_ERROR`` / ``_FATAL`` (once per entry:
      repeated heartbeats in the same state report nothing);
    * every WARNING message → FAILED ``_WARNING`` (warnings are one-shot events; they do not
      change the tracked state, so the heartbeat after one does not count as a new entry);
    * RECOVERING → nothing; RUNNING → PASSED for each code of the node FAILED since its last
      RUNNING (ERROR, FATAL, WARNING, HEARTBEAT_LOST);
    * no message for ``timeout_sec`` (steady clock) → FAILED ``_HEARTBEAT_LOST``, PASSED as soon
      as any message of the node arrives again; after STOPPING silence is a clean exit.
    """

    def __init__(self, timeout_sec: float = HEARTBEAT_TIMEOUT_SEC,
                 severities: Severities | None = None) -> None:
        self.timeout_sec = timeout_sec
        self.severities = severities or Severities()
        self.nodes: dict[str, NodeInfo] = {}

    def on_message(self, nodename: str, state: int, now: float, *, package: str = "",
                   nodetype: str = "", machine_message: str = "",
                   human_message: str = "") -> list[Report]:
        """Reports caused by one message received at ``now`` (steady clock, seconds).

        Raises BadMessage for a message that names no node or carries an unknown state; such a
        message changes nothing (it does not count as a heartbeat either).
        """
        if not upper_snake(nodename):
            raise BadMessage(f"NodeState with unusable nodename {nodename!r}")
        if state not in STATE_NAMES:
            raise BadMessage(f"NodeState from {nodename} with unknown state {state}")
        node = self.nodes.get(nodename)
        if node is None:
            node = self.nodes[nodename] = NodeInfo(nodename)
        node.package, node.nodetype = package, nodetype
        node.last_seen = now
        reports: list[Report] = []
        if node.lost:
            node.lost = False
            if SUFFIX_HEARTBEAT_LOST in node.raised:
                node.raised.remove(SUFFIX_HEARTBEAT_LOST)
            reports.append(self._passed(node, SUFFIX_HEARTBEAT_LOST))
        if state == WARNING:
            reports.append(self._failed(node, SUFFIX_WARNING, self.severities.warning,
                                        describe(human_message, machine_message)))
            return reports
        previous = node.state
        node.state = state
        node.machine_message, node.human_message = machine_message, human_message
        if state == RUNNING:  # also after a WARNING while RUNNING: the state did not change
            reports.extend(self._passed(node, suffix) for suffix in node.raised)
            node.raised.clear()
        elif state != previous and state == ERROR:
            reports.append(self._failed(node, SUFFIX_ERROR, self.severities.error,
                                        describe(human_message, machine_message)))
        elif state != previous and state == FATAL:
            reports.append(self._failed(node, SUFFIX_FATAL, self.severities.fatal,
                                        describe(human_message, machine_message)))
        return reports

    def check(self, now: float) -> list[Report]:
        """FAILED HEARTBEAT_LOST for every node silent for longer than the timeout at ``now``,
        once per silence; a node whose last state was STOPPING exited cleanly."""
        reports: list[Report] = []
        for node in self.nodes.values():
            if node.lost or not heartbeat_lost(node.state, node.last_seen, now,
                                               self.timeout_sec):
                continue
            node.lost = True
            last = STATE_NAMES.get(node.state, "none") if node.state is not None else "none"
            reports.append(self._failed(
                node, SUFFIX_HEARTBEAT_LOST, self.severities.heartbeat_lost,
                f"no heartbeat from {node.nodename} for {self.timeout_sec:g} s "
                f"(last state {last})"))
        return reports

    def _failed(self, node: NodeInfo, suffix: str, severity: int, description: str) -> Report:
        if suffix not in node.raised:
            node.raised.append(suffix)
        return Report("failed", fault_code(node.nodename, prefix=CODE_PREFIX, suffix=suffix),
                      node.nodename, severity, description)

    @staticmethod
    def _passed(node: NodeInfo, suffix: str) -> Report:
        return Report("passed", fault_code(node.nodename, prefix=CODE_PREFIX, suffix=suffix),
                      node.nodename)
