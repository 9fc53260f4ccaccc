"""The identity a log records once (a ``ledger_identified`` record): whose and which log it is."""

from __future__ import annotations

from typing import NamedTuple


class LedgerIdentity(NamedTuple):
    """``robot_id`` names the robot (what its token may push to a fleet's central);
    ``ledger_id`` names this one log (a UUID made when its identity was recorded), so a
    central keeps one hash chain per ledger_id even if a robot's log is ever replaced."""

    robot_id: str
    ledger_id: str
