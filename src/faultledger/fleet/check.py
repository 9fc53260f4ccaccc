"""`verify --central`: the central as the robot's external witness (docs/fleet.md). Every
(seq, hash) the central holds for this log's ledger_id must be in the robot's log, unchanged:
a log truncated, or rewritten and re-chained so that it verifies on its own, is named by the
first seq that is missing or differs. Other logs of the robot the central holds (its database
was replaced: a new ledger_id) are named too: their records are not in this log."""

from __future__ import annotations

from dataclasses import dataclass

from faultledger.domain.identity import LedgerIdentity
from faultledger.fleet.client import (
    CentralClient,
    CentralError,
    HeldLog,
    RecordsPage,
    UnknownLedger,
)
from faultledger.fleet.push import RobotLog

PAGE = 10_000
"""(seq, hash) pairs asked for per request: the protocol's largest page."""


@dataclass(frozen=True, slots=True)
class CentralCheck:
    """What the comparison found; ``problem`` names the first bad seq when not ``ok``."""

    identity: LedgerIdentity
    central: str
    compared: int
    central_seq: int
    """The last seq the central holds for this log (0: none)."""
    head_seq: int
    """The robot log's newest seq."""
    first_bad_seq: int | None = None
    problem: str | None = None
    other_logs: tuple[HeldLog, ...] = ()
    """Other logs of this robot the central holds (a database replaced since): their
    records are not in this log, and never will be."""

    @property
    def ok(self) -> bool:
        return self.problem is None

    @property
    def not_pushed(self) -> int:
        return max(0, self.head_seq - self.central_seq)


def check_against_central(robot_log: RobotLog, client: CentralClient) -> CentralCheck:
    """Page through the central's (seq, hash) pairs of this log and compare each with the
    robot's stored hash; stop at the first that is missing or differs."""
    identity = robot_log.identity()
    head = robot_log.head()
    try:
        others = tuple(log for log in client.robots() if log.robot_id == identity.robot_id
                       and log.ledger_id != identity.ledger_id)
    except CentralError:  # an older central does not let a robot list its logs
        others = ()
    after = 0
    compared = 0
    central_seq = 0
    while True:
        try:
            page = client.records(identity.ledger_id, after, PAGE)
        except UnknownLedger:
            page = RecordsPage([], 0)  # nothing pushed yet: nothing to compare
        central_seq = max(central_seq, page.last_seq)
        if not page.items:
            break
        mine = robot_log.hashes(page.items[0][0], page.items[-1][0])
        for seq, digest in page.items:
            stored = mine.get(seq)
            if stored != digest:
                return CentralCheck(identity, client.shown, compared, central_seq, head, seq,
                                    _problem(seq, digest, stored, head, central_seq), others)
            compared += 1
        after = page.items[-1][0]
        if after >= page.last_seq:
            break
    return CentralCheck(identity, client.shown, compared, central_seq, head, other_logs=others)


def _problem(seq: int, central_hash: str, stored: str | None, head: int,
             central_seq: int) -> str:
    if stored is not None:
        return (f"record seq {seq} differs from the central's copy (central hash "
                f"{central_hash}, this log's {stored}): the log was rewritten from there")
    if seq > head:
        return (f"record seq {seq} is missing from this log: it ends at seq {head}, the "
                f"central holds records up to seq {central_seq}; the log was truncated")
    return (f"record seq {seq} is missing from this log (the central holds it, hash "
            f"{central_hash}): it was deleted")
