"""`~/acknowledge_fault` against a real fault manager (issue 21): recorded with the caller's
actor for the current episode, a second call records nothing, refusals store nothing, and
the medkit events topic carries no event type a medkit subscriber does not know."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from faultledger_msgs.srv import AcknowledgeFault

from faultledger import FaultLedger

if TYPE_CHECKING:
    from tests.ros.conftest import EventRecorder, ManagerFactory, RosClient

NS = "/fault_manager"


def acknowledge(ros: RosClient, code: str, actor: str = "", note: str = "") -> Any:
    return ros.call(AcknowledgeFault, f"{NS}/acknowledge_fault",
                    AcknowledgeFault.Request(fault_code=code, actor=actor, note=note))


def test_acknowledge_fault_records_the_current_episode_once(
        manager: ManagerFactory, client: RosClient, events: EventRecorder) -> None:
    fm = manager()
    events.wait_matched()
    assert client.report("ACK_LIDAR", severity=2)
    first = acknowledge(client, "ACK_LIDAR", actor="ros:operator-panel", note="wiping it")
    assert (first.success, first.recorded, first.episode) == (True, True, 1), first.message
    again = acknowledge(client, "ACK_LIDAR")
    assert (again.success, again.recorded) == (True, False)
    assert "already acknowledged by ros:operator-panel" in again.message
    unknown = acknowledge(client, "ACK_NEVER")
    assert (unknown.success, unknown.message) == (False, "Fault not found: ACK_NEVER")
    bad = acknowledge(client, "ACK LIDAR")
    assert not bad.success and "invalid character ' '" in bad.message
    cleared = client.clear("ACK_LIDAR")
    assert cleared.success
    late = acknowledge(client, "ACK_LIDAR")
    assert not late.success and "CLEARED" in late.message
    assert client.report("ACK_LIDAR", severity=2)  # episode 2 needs its own
    second = acknowledge(client, "ACK_LIDAR")
    assert (second.success, second.recorded, second.episode) == (True, True, 2)
    events.settle()
    kinds = {message.event_type for message in events.of("ACK_LIDAR")}
    assert kinds == {"fault_confirmed", "fault_cleared"}  # medkit's types only
    assert fm.stop() == 0
    with FaultLedger.open(f"sqlite:///{fm.db_path}") as ledger:
        fault = ledger.get_fault("ACK_LIDAR")
        acks = ledger.history(code="ACK_LIDAR", kinds=("fault_acknowledged",))
    assert fault is not None and fault.acknowledged is not None
    assert fault.acknowledged.actor == "ros:acknowledge_fault"
    assert [(r.payload["actor"], r.payload["episode"], r.payload["note"]) for r in acks] == [
        ("ros:operator-panel", 1, "wiping it"), ("ros:acknowledge_fault", 2, "")]
