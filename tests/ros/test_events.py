"""The /fault_manager/events stream seen from another process (this one): exactly SPEC §4.4.

Each scripted step states the event it must cause (or none). After a step that causes one, the
fault is read back with get_fault: the event must carry exactly that full fault state.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

from ros2_medkit_msgs.msg import FaultEvent

if TYPE_CHECKING:
    from tests.ros.conftest import EventRecorder, ManagerFactory, RosClient

FAILED, PASSED = 0, 1
CONFIRMED = FaultEvent.EVENT_CONFIRMED
UPDATED = FaultEvent.EVENT_UPDATED
CLEARED = FaultEvent.EVENT_CLEARED


def stamp_ns(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def describe(messages: list[Any]) -> str:
    return "\n".join(f"  {m.event_type:16} {m.fault.fault_code:12} {m.fault.status:10} "
                     f"count={m.fault.occurrence_count}" for m in messages)


class Script:
    """Runs steps against the manager and records the events they must cause."""

    def __init__(self, client: RosClient) -> None:
        self.client = client
        self.expected: list[tuple[str, Any]] = []

    def report(self, code: str, event_type: int, expect: str | None, severity: int = 1,
               description: str = "", source: str = "/ev/a") -> None:
        assert self.client.report(code, event_type, severity, description, source), (
            code, event_type)
        self._expect(code, expect)

    def clear(self, code: str, expect: str | None) -> None:
        assert self.client.clear(code).success
        self._expect(code, expect)

    def _expect(self, code: str, expect: str | None) -> None:
        if expect is not None:
            self.expected.append((expect, self.client.fault(code)))

    def status(self, code: str) -> str:
        status: str = self.client.fault(code).status
        return status


def assert_events(events: EventRecorder, expected: list[tuple[str, Any]]) -> None:
    """Exactly the expected events, in order, each with the full fault state; nothing else."""
    synced = len(events.messages) - len(events.scenario())
    events.wait_for_count(synced + len(expected), timeout=10.0)
    events.settle(1.0)  # late, unexpected events must have a chance to show up
    received = events.scenario()
    wanted = "\n".join(f"  {kind:16} {fault.fault_code:12} {fault.status}"
                       for kind, fault in expected)
    assert [(m.event_type, m.fault.fault_code) for m in received] == [
        (kind, fault.fault_code) for kind, fault in expected], (
        f"received:\n{describe(received)}\nexpected:\n{wanted}")
    for message, (_, fault) in zip(received, expected, strict=True):
        assert message.fault == fault, f"{message.event_type}: {message.fault} != {fault}"
        assert list(message.auto_cleared_codes) == []
        assert stamp_ns(message.timestamp) >= stamp_ns(fault.first_occurred) > 0
    stamps = [stamp_ns(m.timestamp) for m in received]
    assert stamps == sorted(stamps)


def test_events_follow_the_debounce_scenario(manager: ManagerFactory, client: RosClient,
                                             events: EventRecorder) -> None:
    manager("--ros-args", "-p", "confirmation_threshold:=-2", "-p", "healing_enabled:=true",
            "-p", "healing_threshold:=2")
    events.wait_matched()
    run = Script(client)

    # New fault: PREFAILED (no event), then CONFIRMED by debounce.
    run.report("EV_A", FAILED, None, severity=1, description="a1", source="/ev/a")
    assert run.status("EV_A") == "PREFAILED"
    run.report("EV_A", FAILED, CONFIRMED, severity=2, description="a2", source="/ev/b")
    # Reports that leave it CONFIRMED: fault_updated (FAILED and PASSED alike).
    run.report("EV_A", FAILED, UPDATED, severity=1, source="/ev/a")       # counter stays -2
    run.report("EV_A", PASSED, UPDATED, source="/ev/c")                    # -1, latched
    run.report("EV_A", PASSED, UPDATED)                                    # 0
    run.report("EV_A", PASSED, UPDATED)                                    # 1
    # Healing: fault_cleared with status HEALED; reports that keep it HEALED: nothing.
    run.report("EV_A", PASSED, CLEARED)                                    # 2 -> HEALED
    assert run.status("EV_A") == "HEALED"
    run.report("EV_A", PASSED, None)                                       # clamped at 2
    run.report("EV_A", FAILED, None)                                       # 1, HEALED latched
    run.report("EV_A", FAILED, None)                                       # 0
    run.report("EV_A", FAILED, None)                                       # -1
    assert run.status("EV_A") == "HEALED"
    run.report("EV_A", FAILED, CONFIRMED)                                  # -2: HEALED->CONFIRMED
    # Clear: fault_cleared with status CLEARED, also for an already CLEARED fault.
    run.clear("EV_A", CLEARED)
    run.clear("EV_A", CLEARED)
    run.report("EV_A", PASSED, None)                                       # ignored on CLEARED
    # Reactivation: PREFAILED (no event), then CONFIRMED with occurrence_count 2.
    run.report("EV_A", FAILED, None, severity=0)
    assert run.status("EV_A") == "PREFAILED"
    run.report("EV_A", FAILED, CONFIRMED, severity=0)
    assert client.fault("EV_A").occurrence_count == 2

    # Born CONFIRMED: a CRITICAL first report.
    run.report("EV_CRIT", FAILED, CONFIRMED, severity=3, description="e-stop")
    # CRITICAL on a PREFAILED fault confirms at once.
    run.report("EV_JUMP", FAILED, None, severity=1)
    run.report("EV_JUMP", FAILED, CONFIRMED, severity=3)
    # PREFAILED <-> PREPASSED moves: never an event.
    run.report("EV_PRE", FAILED, None)                                     # -1 PREFAILED
    run.report("EV_PRE", PASSED, None)                                     # 0
    run.report("EV_PRE", PASSED, None)                                     # 1 PREPASSED
    assert run.status("EV_PRE") == "PREPASSED"
    run.report("EV_PRE", FAILED, None)                                     # 0
    run.report("EV_PRE", FAILED, None)                                     # -1 PREFAILED
    assert run.status("EV_PRE") == "PREFAILED"
    # PASSED for an unknown fault, rejected reports and a failed clear: nothing.
    run.report("EV_NEVER", PASSED, None)
    assert not client.get("EV_NEVER").success
    assert not client.report("EV BAD", FAILED, 3, "", "/ev/a")
    assert not client.report("EV_BAD_SEVERITY", FAILED, 7, "", "/ev/a")
    assert not client.report("EV_BAD_SOURCE", FAILED, 3, "", "")
    assert not client.clear("EV_UNKNOWN").success
    assert not client.clear("EV..X").success

    assert_events(events, run.expected)


def test_timer_confirmation_is_announced(manager: ManagerFactory, client: RosClient,
                                         events: EventRecorder) -> None:
    manager("--ros-args", "-p", "confirmation_threshold:=-3", "-p", "auto_confirm_after_sec:=1.0")
    events.wait_matched()
    assert client.report("EV_TIMER", FAILED, 2, "slow drift", "/ev/timer")
    reported_at = time.monotonic()
    assert client.fault("EV_TIMER").status == "PREFAILED"
    assert client.report("EV_TIMER_STAYS", FAILED, 1, "", "/ev/timer")
    assert client.report("EV_TIMER_STAYS", PASSED, 0, "", "/ev/timer")  # counter 0: PREFAILED
    assert client.report("EV_TIMER_STAYS", PASSED, 0, "", "/ev/timer")  # 1: PREPASSED

    assert client.spin_until(lambda: bool(events.of("EV_TIMER")), 10.0), (
        "no event for the timer-confirmed fault")
    assert time.monotonic() - reported_at >= 0.9, "confirmed before auto_confirm_after_sec"
    fault = client.fault("EV_TIMER")
    assert fault.status == "CONFIRMED"
    assert client.fault("EV_TIMER_STAYS").status == "PREPASSED"
    assert_events(events, [(CONFIRMED, fault)])
    kinds = [r.kind for r in client.history(fault_code="EV_TIMER").records]
    assert kinds == ["fault_reported", "fault_confirmed_by_timer"]
