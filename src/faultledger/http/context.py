"""What every route module gets: the ledger, the authorizer, the stream hub, the calendar,
the pool of heavy reads."""

from __future__ import annotations

from dataclasses import dataclass, field

from faultledger.domain.shifts import ShiftCalendar
from faultledger.http.auth import Authorizer
from faultledger.http.heavy import HeavyReads
from faultledger.http.stream import StreamHub
from faultledger.service.config import HttpSettings
from faultledger.service.fleet import Fleet
from faultledger.service.ledger import FaultLedger


@dataclass(slots=True)
class Context:
    ledger: FaultLedger
    settings: HttpSettings
    calendar: ShiftCalendar
    auth: Authorizer
    hub: StreamHub
    read_only: bool = False
    """A follower (``serve --follower --http``): every mutation answers 503 ``unavailable``."""
    heavy: HeavyReads = field(default_factory=lambda: HeavyReads(1, 16, 10.0))
    """The pool statistics, history, state-at and shift reports are computed in."""
    fleet: Fleet | None = None
    """The robot logs this server holds as a fleet central (made by the app)."""
    fleet_labels: dict[str, dict[str, str]] = field(default_factory=dict)
    """Per robot_id its ``line`` and ``site`` (the config's ``fleet.robots``): what
    ``group_by=line|site`` groups by."""
    pushes: HeavyReads = field(default_factory=lambda: HeavyReads(
        PUSH_SLOTS, PUSH_QUEUE, PUSH_WAIT_SEC, what="robot log batches",
        settings="{slots} at a time, {queue} waiting"))
    """Where a fleet central checks and stores robots' batches: four at a time however many
    robots push (a batch spends most of its time waiting for PostgreSQL's round trips, which
    the others fill; more threads would only fight over the interpreter). Measured with
    bench/fleet.py, 20 robots: 19,455–22,499 records/s with two, 21,580–30,773 with four."""


    def robot_logs(self) -> Fleet:
        assert self.fleet is not None, "the app makes the fleet"
        return self.fleet


PUSH_SLOTS = 4
PUSH_QUEUE = 256
PUSH_WAIT_SEC = 30.0
