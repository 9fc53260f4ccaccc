"""A status change of one fault: shared by the projector and the statistics fold."""

from __future__ import annotations

from typing import NamedTuple

from faultledger.domain.types import FaultStatus


class Transition(NamedTuple):
    """A status change of one fault, caused by the record ``seq`` (from_status None: created)."""

    seq: int
    fault_code: str
    from_status: FaultStatus | None
    to_status: FaultStatus
    at_ns: int
    cause: str
    source_id: str
