"""The operator's figures on a worked example (docs/statistics.md, "The operator's day"):
MTTA runs from the episode's first confirmation, not its first FAILED; an acknowledgement
before the confirmation counts but has no MTTA; shelved time stops at the end record, or at
the expiry while none is recorded; both statistics paths agree; grouped by source, the
actor's row carries them."""

from __future__ import annotations

from collections.abc import Callable
from datetime import UTC, datetime, timedelta

from faultledger import FaultLedger, Policy

T0 = datetime(2026, 11, 23, 6, 0, tzinfo=UTC)


def minutes(n: float) -> datetime:
    return T0 + timedelta(minutes=n)


def test_mtta_counts_from_the_confirmation_and_shelving_from_record_to_end(
        fresh_url: Callable[[str], str]) -> None:
    policy = Policy(confirmation_threshold=-3)
    with FaultLedger.open(fresh_url("operator"), policy=policy, background=False) as ledger:
        for n in (0, 1, 2):  # the third FAILED confirms, at minute 2
            assert ledger.report("ARM_JAM", "FAILED", 2, source_id="/arm", at=minutes(n)).accepted
        assert ledger.acknowledge("ARM_JAM", "cli:alice", at=minutes(7)).success  # 5 min
        assert ledger.report("DOCK_IR", "FAILED", 1, source_id="/dock", at=minutes(10)).accepted
        assert ledger.acknowledge("DOCK_IR", "cli:bob", at=minutes(11)).success  # PREFAILED
        assert ledger.shelve("DOCK_IR", timedelta(minutes=30), "cli:bob", at=minutes(20)).success
        assert ledger.unshelve("DOCK_IR", "cli:bob", at=minutes(35)).success  # 15 min
        assert ledger.shelve("ARM_JAM", timedelta(minutes=20), "cli:alice",
                             at=minutes(40)).success  # no end recorded: expiry at minute 60
        for codes in (None, ["*"]):  # the per-minute sums and the facts path
            [row] = ledger.stats("day", T0, T0 + timedelta(hours=2), codes=codes,
                                 as_of=T0 + timedelta(hours=2))
            assert row.acknowledgements == 2
            assert row.mtta_seconds == 300.0  # bob's acknowledgement has no confirmation
            assert row.shelved_seconds == 15 * 60 + 20 * 60
        rows = ledger.stats("hour", T0, T0 + timedelta(hours=2), group_by=["source"],
                            as_of=T0 + timedelta(hours=2))
        alice = [r for r in rows if r.group == {"source": "cli:alice"}]
        assert [(r.period.start, r.acknowledgements, r.shelved_seconds) for r in alice] == [
            (T0, 1, 1200.0)]
        bob = [r for r in rows if r.group == {"source": "cli:bob"}]
        assert [(r.acknowledgements, r.mtta_seconds, r.shelved_seconds) for r in bob] == [
            (1, None, 900.0)]
