"""What every route module gets: the ledger, the authorizer, the stream hub, the calendar,
the pool of heavy reads."""

from __future__ import annotations

from dataclasses import dataclass, field

from faultledger.domain.shifts import ShiftCalendar
from faultledger.http.auth import Authorizer
from faultledger.http.heavy import HeavyReads
from faultledger.http.stream import StreamHub
from faultledger.service.config import HttpSettings
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
