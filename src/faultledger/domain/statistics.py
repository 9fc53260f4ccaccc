"""The statistics fold: which records count as what (docs/statistics.md, "What is counted").

It rides along the Projector, so every path that applies records (append, replay, catch-up,
rebuild) derives the same facts. Its per-code state is small and persisted with the
projections, so a restart continues the fold instead of re-reading the log.
"""

from __future__ import annotations

from typing import NamedTuple

from faultledger.domain.events import (
    FaultAcknowledged,
    FaultReported,
    FaultShelved,
    GoalOutcome,
    LogRecord,
    OperatorEvent,
)
from faultledger.domain.fault import Fault
from faultledger.domain.transition import Transition
from faultledger.domain.types import EventType, FaultStatus, tuple_new

CHATTER_WINDOW_NS = 60 * 1_000_000_000
"""Three activations of one code within less than this are chattering (ISA-18.2)."""


class StatFact(NamedTuple):
    """What one record counts for; flags are 0/1 so sums are counts."""

    seq: int
    at_ns: int
    code: str
    source: str
    severity: int
    failed: int = 0
    passed: int = 0
    activation: int = 0
    occurrence: int = 0
    confirmation: int = 0
    heal: int = 0
    clear: int = 0
    chatter: int = 0


class GoalFact(NamedTuple):
    """One goal outcome record: the terminal status of one action goal."""

    seq: int
    at_ns: int
    action: str
    status: str
    """SUCCEEDED, ABORTED or CANCELED."""
    server_node: str


class Episode(NamedTuple):
    """Time in CONFIRMED, owned by the code, source and severity of the confirming fact.

    ``end_ns`` is the time of the record that ended it. When the reporter's clock ran
    backwards that is before ``start_ns``: the episode then lasts 0 s (``stop_ns``).
    """

    start_seq: int
    code: str
    source: str
    severity: int
    start_ns: int
    end_seq: int | None = None
    end_ns: int | None = None

    @property
    def repair_ns(self) -> int:
        return 0 if self.end_ns is None else max(0, self.end_ns - self.start_ns)

    def stop_ns(self, as_of_ns: int) -> int:
        """Where the time in CONFIRMED ends: never before the start; ``as_of`` while open."""
        return max(self.start_ns, as_of_ns if self.end_ns is None else self.end_ns)


class OperatorFact(NamedTuple):
    """What people did (docs/statistics.md, "The operator's day"): an acknowledgement, at its
    time, with its delay from the episode's first confirmation (None: acknowledged before it
    was confirmed); or a shelving, from ``at_ns`` to ``end_ns`` (None while it lasts). Each
    belongs to the code, the actor (its ``source``) and the fault's severity then."""

    seq: int
    kind: str
    """``ack`` or ``shelf``."""
    code: str
    source: str
    severity: int
    at_ns: int
    delay_ns: int | None = None
    until_ns: int | None = None
    """A shelving's expiry, as its record set it."""
    end_seq: int | None = None
    end_ns: int | None = None

    def stop_ns(self, as_of_ns: int) -> int:
        """Where a shelving's time ends: its end record; while none is recorded, its expiry
        or ``as_of``, whichever is first (a stopped server records the end when it starts);
        never before its start."""
        if self.end_ns is not None:
            return max(self.at_ns, self.end_ns)
        return max(self.at_ns, min(as_of_ns, self.until_ns or as_of_ns))


ACK, SHELF = "ack", "shelf"


class CodeTrack(NamedTuple):
    """The fold's memory of one code."""

    last_failed: bool = False
    activations: tuple[int, ...] = ()
    """Times of the last two activations, oldest first (for chattering)."""
    episode: Episode | None = None
    """The open CONFIRMED episode."""


class StatsOutput(NamedTuple):
    """What records applied since the last ``take`` produced, for the store to persist."""

    facts: list[StatFact]
    started: list[Episode]
    """Episodes that began (their latest version: possibly already ended)."""
    ended: list[Episode]
    """Episodes that ended (with their start)."""
    tracks: dict[str, CodeTrack]
    goals: list[GoalFact]
    """Goal outcomes, in seq order."""
    operator: list[OperatorFact]
    """Acknowledgements and shelvings that began, in seq order."""
    shelf_ends: list[tuple[int, int, int]]
    """(start seq, end seq, end ns) of shelvings that ended (maybe begun in this output)."""


def _empty_output() -> StatsOutput:
    return StatsOutput([], [], [], {}, [], [], [])


def is_chattering(times: tuple[int, ...]) -> bool:
    return len(times) >= 3 and max(times[-3:]) - min(times[-3:]) < CHATTER_WINDOW_NS


class StatsFold:
    """Stats facts from (record, transition, fault after); staged like the Projector."""

    def __init__(self, tracks: dict[str, CodeTrack] | None = None) -> None:
        self._tracks: dict[str, CodeTrack] = dict(tracks or {})
        self._staged: dict[str, CodeTrack] | None = None
        self._out = _empty_output()
        self._started_at: dict[int, int] = {}
        """start_seq → index in ``_out.started`` (ending an episode finds it in O(1))."""
        self._saved_len: tuple[int, ...] | None = None
        self._undo: dict[str, CodeTrack | None] = {}
        """While staged: each code's entry in the output's tracks before the stage touched it
        (None: it had none). An undo log, not a copy: staging costs nothing however many
        codes the output holds."""
        self._replaced: list[tuple[int, Episode]] = []
        """While staged: (index, episode before) of the output's started episodes the stage
        ended in place (``_replace_started``), so a rollback restores them."""

    def track(self, code: str) -> CodeTrack:
        if self._staged is not None and code in self._staged:
            return self._staged[code]
        return self._tracks.get(code, _NEW)

    def tracks(self) -> dict[str, CodeTrack]:
        merged = dict(self._tracks)
        if self._staged:
            merged.update(self._staged)
        return merged

    # -- staging (mirrors Projector) --------------------------------------------------------
    def stage(self) -> None:
        self._staged = {}
        self._saved_len = (len(self._out.facts), len(self._out.started), len(self._out.ended),
                           len(self._out.goals), len(self._out.operator),
                           len(self._out.shelf_ends))
        self._undo = {}

    def commit(self) -> None:
        if self._staged:
            self._tracks.update(self._staged)
        self._staged = None
        self._saved_len = None
        self._undo = {}
        self._replaced = []

    def rollback(self) -> None:
        if self._saved_len is not None:
            facts, started, ended, goals, operator, shelf_ends = self._saved_len
            del self._out.facts[facts:]
            del self._out.started[started:]
            del self._out.ended[ended:]
            del self._out.goals[goals:]
            del self._out.operator[operator:]
            del self._out.shelf_ends[shelf_ends:]
            tracks = self._out.tracks
            for code, before in self._undo.items():
                if before is None:
                    del tracks[code]
                else:
                    tracks[code] = before
            for index, episode in reversed(self._replaced):
                if index < started:
                    self._out.started[index] = episode
            self._started_at = {e.start_seq: i for i, e in enumerate(self._out.started)}
        self._staged = None
        self._saved_len = None
        self._undo = {}
        self._replaced = []

    def peek(self) -> StatsOutput:
        """What was produced since the last ``take``, staged part included, kept: saved
        within a transaction that may still fail, and taken once it committed."""
        return self._out

    def take(self) -> StatsOutput:
        """Hand over (and forget) what was produced since the last call."""
        out = self._out
        self._out = _empty_output()
        self._started_at = {}
        if self._saved_len is not None:
            self._saved_len = (0, 0, 0, 0, 0, 0)
            self._undo = {}
            self._replaced = []
        return out

    def _put(self, code: str, track: CodeTrack) -> None:
        if self._staged is not None:
            self._staged[code] = track
            if code not in self._undo:
                self._undo[code] = self._out.tracks.get(code)
        else:
            self._tracks[code] = track
        self._out.tracks[code] = track

    # -- the fold -----------------------------------------------------------------------------
    def observe_goal(self, record: LogRecord, event: GoalOutcome) -> None:
        """A goal outcome is its own fact: it touches no code's state."""
        self._out.goals.append(GoalFact(record.seq, record.occurred_at_ns, event.action,
                                        event.status, event.server_node))

    def observe_operator(self, record: LogRecord, event: OperatorEvent, before: Fault,
                         after: Fault) -> None:
        """An acknowledgement or shelving that changed the fault (``after``). A shelving of
        a shelved fault ends the running one and starts another at the same instant (the
        shelved time adds up the same); an end closes the running one."""
        at = record.occurred_at_ns
        if isinstance(event, FaultAcknowledged):
            delay = None if not after.confirmed_ns or at < after.confirmed_ns else (
                at - after.confirmed_ns)
            self._out.operator.append(OperatorFact(record.seq, ACK, event.fault_code,
                                                   event.actor, after.severity, at, delay))
            return
        if before.shelved is not None:
            self._out.shelf_ends.append((before.shelved.seq, record.seq, at))
        if isinstance(event, FaultShelved):
            self._out.operator.append(OperatorFact(record.seq, SHELF, event.fault_code,
                                                   event.actor, after.severity, at,
                                                   until_ns=event.until_ns))

    def observe(self, record: LogRecord, transition: Transition | None,
                fault: Fault | None) -> None:
        event = record.event
        report = event if isinstance(event, FaultReported) else None
        if report is None and transition is None:
            return
        code = report.fault_code if report is not None else transition.fault_code  # type: ignore[union-attr]
        track = self.track(code)
        at = record.occurred_at_ns
        failed = report is not None and report.event_type is EventType.FAILED
        activation = failed and not track.last_failed
        chatter = False
        activations = track.activations
        if activation:
            activations = (*activations, at)
            chatter = is_chattering(activations)
            activations = activations[-2:]
        last_failed = failed if report is not None else track.last_failed
        to = transition.to_status if transition is not None else None
        came = transition.from_status if transition is not None else None
        if to is FaultStatus.CLEARED:
            last_failed = False
        source = transition.source_id if transition is not None else report.source_id  # type: ignore[union-attr]
        severity = fault.severity if fault is not None else (
            report.severity if report is not None else 0)
        fact: StatFact = tuple_new(StatFact, (  # once per record: see tuple_new
            record.seq, at, code, source, severity,
            int(failed),  # failed
            int(report is not None and not failed),  # passed
            int(activation),  # activation
            int(failed and transition is not None  # occurrence
                and (came is None or came is FaultStatus.CLEARED)),
            int(to is FaultStatus.CONFIRMED),  # confirmation
            int(to is FaultStatus.HEALED),  # heal
            int(to is FaultStatus.CLEARED),  # clear
            int(chatter),  # chatter
        ))
        self._out.facts.append(fact)
        episode = track.episode
        if came is FaultStatus.CONFIRMED and episode is not None:
            ended = episode._replace(end_seq=record.seq, end_ns=at)
            self._out.ended.append(ended)
            self._replace_started(ended)
            episode = None
        if to is FaultStatus.CONFIRMED:
            episode = Episode(record.seq, code, source, severity, at)
            self._started_at[record.seq] = len(self._out.started)
            self._out.started.append(episode)
        self._put(code, tuple_new(CodeTrack, (last_failed, activations, episode)))

    def _replace_started(self, ended: Episode) -> None:
        """An episode that starts and ends in one output is written once, ended."""
        index = self._started_at.get(ended.start_seq)
        if index is not None:
            if self._saved_len is not None:
                self._replaced.append((index, self._out.started[index]))
            self._out.started[index] = ended


_NEW = CodeTrack()
