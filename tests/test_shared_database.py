"""Two ledgers (as two processes would) on one database: one gap-free log, shared state
(SQLite file, or PostgreSQL with ``--backend postgresql``)."""

from __future__ import annotations

from faultledger import FaultLedger, FaultStatus, Policy


def test_second_writer_sees_faults_the_first_one_created(db_url: str) -> None:
    with FaultLedger.open(db_url, policy=Policy()) as first, \
            FaultLedger.open(db_url) as second:
        assert first.report("MOTOR_OVERHEAT", "FAILED", 2, "", "/motor").accepted
        cleared = second.clear("MOTOR_OVERHEAT", actor="cli:alice")
        assert cleared.success, cleared.message
        fault = second.get_fault("MOTOR_OVERHEAT")
        assert fault is not None and fault.status is FaultStatus.CLEARED


def test_alternating_writers_keep_one_gap_free_verifiable_log(db_url: str) -> None:
    with FaultLedger.open(db_url, policy=Policy(confirmation_threshold=-2)) as a, \
            FaultLedger.open(db_url) as b:
        for i in range(20):
            writer = a if i % 2 == 0 else b
            assert writer.report("LIDAR_TIMEOUT", "FAILED", 1, "", f"/lidar{i % 3}").accepted
        records = a.history()
        assert [r.seq for r in records] == list(range(1, len(records) + 1))
        assert a.verify().ok
        b.report("LIDAR_TIMEOUT", "PASSED", 0, "", "/lidar0")
        a.report("LIDAR_TIMEOUT", "PASSED", 0, "", "/lidar0")
        fault = a.get_fault("LIDAR_TIMEOUT")
        assert fault is not None and fault.debounce_counter == 0  # -2 (clamped) + 2 PASSED
        assert a.all_faults() == a.state_at(a.last_seq)


def test_a_passed_for_a_fault_created_elsewhere_is_recorded_not_ignored(db_url: str) -> None:
    with FaultLedger.open(db_url, policy=Policy()) as a, \
            FaultLedger.open(db_url) as b:
        assert b.get_fault("ARM_STALL") is None
        a.report("ARM_STALL", "FAILED", 2, "", "/arm")
        result = b.report("ARM_STALL", "PASSED", 0, "", "/arm")
        assert result.seq is not None, result.message
        fault = b.get_fault("ARM_STALL")
        assert fault is not None and fault.debounce_counter == 0


def test_reopened_state_after_two_writers_equals_full_replay(db_url: str) -> None:
    with FaultLedger.open(db_url, policy=Policy()) as a, \
            FaultLedger.open(db_url) as b:
        a.report("A", "FAILED", 2, "", "/x")
        b.report("B", "FAILED", 3, "", "/y")
        a.clear("B", actor="test")
        b.report("A", "PASSED", 0, "", "/x")
    with FaultLedger.open(db_url) as reopened:
        assert reopened.all_faults() == reopened.state_at(reopened.last_seq)
        assert reopened.verify().ok
