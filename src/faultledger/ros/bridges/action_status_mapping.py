"""Action status → fault transitions and goal outcomes: the pure part of the action-status
bridge (no rclpy).

An action server publishes ``/<action>/_action/status`` (``action_msgs/GoalStatusArray``) on
every goal state change: the status of every goal it still remembers (rcl_action keeps finished
goals for ``result_timeout``, 15 minutes by default). The bridge turns those arrays into one
edge-triggered state per action, so a robot that retries a failing goal ten times gets one
FAILED, and one PASSED once the action is judged healthy again.

Which goals are judged (``Rules.judge``):

* ``whole_array`` (default; the seed semantics of SPEC §8, a drop-in for ros2_medkit's bridge):
  every goal of the array. As long as the server still remembers an ABORTED goal the action is
  failed, so a success heals only once the aborted goals have left the array.
* ``new_goals``: the goals whose status is new compared with the previous array received for
  the action (every goal of the first array). A success heals at once, even while old ABORTED
  goals are still remembered.

Among the goals judged, any ABORTED (or CANCELED when ``canceled_is_fault``) makes the action
failed, in whatever order they appear; else any terminal goal makes it healthy; else (only
ACCEPTED/EXECUTING/CANCELING/UNKNOWN, unknown values, an empty array, or nothing new) the state
stays as it was.

Separately from the faults, each goal's terminal status becomes one goal outcome record
(``RecordedGoals``), whatever the judgement: aborts are counted per goal.
"""

from __future__ import annotations

import uuid
from collections import OrderedDict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from enum import Enum
from typing import Literal

from faultledger.ros.bridges.codes import fault_code

STATUS_TOPIC_SUFFIX = "/_action/status"
STATUS_TYPE = "action_msgs/msg/GoalStatusArray"

# action_msgs/msg/GoalStatus constants.
STATUS_UNKNOWN = 0
STATUS_ACCEPTED = 1
STATUS_EXECUTING = 2
STATUS_CANCELING = 3
STATUS_SUCCEEDED = 4
STATUS_CANCELED = 5
STATUS_ABORTED = 6

STATUS_NAMES = {
    STATUS_UNKNOWN: "UNKNOWN", STATUS_ACCEPTED: "ACCEPTED", STATUS_EXECUTING: "EXECUTING",
    STATUS_CANCELING: "CANCELING", STATUS_SUCCEEDED: "SUCCEEDED", STATUS_CANCELED: "CANCELED",
    STATUS_ABORTED: "ABORTED",
}
TERMINAL = frozenset({STATUS_SUCCEEDED, STATUS_CANCELED, STATUS_ABORTED})

MAX_GOALS_IN_DESCRIPTION = 5

Goal = tuple[bytes, int]
"""(goal_id uuid bytes, status) as carried by one GoalStatus."""

Judge = Literal["whole_array", "new_goals"]
WHOLE_ARRAY: Judge = "whole_array"
NEW_GOALS: Judge = "new_goals"


def status_name(status: int) -> str:
    return STATUS_NAMES.get(status, f"INVALID({status})")


def goal_text(goal_id: bytes) -> str:
    """A goal id as the usual UUID text (raw hex when it is not 16 bytes)."""
    return str(uuid.UUID(bytes=goal_id)) if len(goal_id) == 16 else goal_id.hex()


def action_of_topic(topic: str) -> str | None:
    """``/robot1/navigate_to_pose/_action/status`` → ``/robot1/navigate_to_pose``; else None."""
    if topic.endswith(STATUS_TOPIC_SUFFIX) and len(topic) > len(STATUS_TOPIC_SUFFIX):
        return topic[: -len(STATUS_TOPIC_SUFFIX)]
    return None


def is_watched(action: str, exclude: Sequence[str], include_only: Sequence[str]) -> bool:
    """Unanchored substring filters; an exclude match wins, an empty include_only means all."""
    if any(pattern in action for pattern in exclude):
        return False
    return not include_only or any(pattern in action for pattern in include_only)


class Net(Enum):
    FAILED = "failed"
    HEALTHY = "healthy"
    UNCHANGED = "unchanged"


@dataclass(frozen=True)
class Verdict:
    """What an array says about its action; ``failing`` maps each fault suffix to its goals."""

    net: Net
    failing: dict[str, list[Goal]] = field(default_factory=dict)


def net_state(goals: Iterable[Goal], canceled_is_fault: bool) -> Verdict:
    """The net state of these goals: any failure wins, regardless of order (module docstring)."""
    failing: dict[str, list[Goal]] = {}
    terminal = False
    for goal_id, status in goals:
        if status == STATUS_ABORTED or (status == STATUS_CANCELED and canceled_is_fault):
            failing.setdefault(STATUS_NAMES[status], []).append((goal_id, status))
        elif status in TERMINAL:
            terminal = True
    if failing:
        return Verdict(Net.FAILED, failing)
    return Verdict(Net.HEALTHY if terminal else Net.UNCHANGED)


@dataclass(frozen=True)
class Transition:
    """One report to make: FAILED (``passed`` False, with severity and description) or PASSED."""

    code: str
    passed: bool
    severity: int = 0
    description: str = ""


@dataclass
class _ActionState:
    last: dict[bytes, int] = field(default_factory=dict)  # the previous array, goal → status
    raised: list[str] = field(default_factory=list)  # codes reported FAILED, not yet healed

    @property
    def failed(self) -> bool:
        return bool(self.raised)


@dataclass(frozen=True)
class Rules:
    code_prefix: str = "ACTION"
    severity: int = 2
    canceled_is_fault: bool = False
    heal_on_succeeded: bool = True
    judge: Judge = WHOLE_ARRAY


class ActionTracker:
    """Per-action state (initially healthy); yields the transitions to report."""

    def __init__(self, rules: Rules) -> None:
        self.rules = rules
        self._actions: dict[str, _ActionState] = {}

    def failed(self, action: str) -> bool:
        state = self._actions.get(action)
        return state is not None and state.failed

    def observe(self, action: str, goals: Sequence[Goal]) -> list[Transition]:
        """One status array of ``action``: FAILED on healthy→failed, PASSED on failed→healthy.

        Judged on the whole array, or on the goals whose status is new (``Rules.judge``)."""
        state = self._actions.setdefault(action, _ActionState())
        judged = list(goals)
        if self.rules.judge == NEW_GOALS:
            judged = [(goal_id, status) for goal_id, status in goals
                      if state.last.get(goal_id) != status]
        state.last = dict(goals)
        verdict = net_state(judged, self.rules.canceled_is_fault)
        if verdict.net is Net.FAILED:
            out = []
            for suffix, failing in verdict.failing.items():
                code = fault_code(action, prefix=f"{self.rules.code_prefix}_", suffix=suffix)
                if code not in state.raised:  # a new kind of failure is its own edge
                    state.raised.append(code)
                    out.append(Transition(code, False, self.rules.severity,
                                          describe(action, suffix, failing)))
            return out
        if verdict.net is Net.HEALTHY:
            return self._heal(state)
        return []

    def drop(self, action: str) -> list[Transition]:
        """The action vanished: forget it, healing it first when it was failed."""
        state = self._actions.pop(action, None)
        return self._heal(state) if state is not None else []

    def _heal(self, state: _ActionState) -> list[Transition]:
        raised, state.raised = state.raised, []
        if not self.rules.heal_on_succeeded:
            return []
        return [Transition(code, True) for code in raised]


def describe(action: str, suffix: str, goals: Sequence[Goal]) -> str:
    """``action /navigate_to_pose: goal 5f1c… ABORTED`` naming (up to 5 of) the goals."""
    shown = ", ".join(goal_text(goal_id) for goal_id, _ in goals[:MAX_GOALS_IN_DESCRIPTION])
    more = len(goals) - MAX_GOALS_IN_DESCRIPTION
    if more > 0:
        shown += f" and {more} more"
    noun = "goal" if len(goals) == 1 else "goals"
    return f"action {action}: {noun} {shown} {suffix}"


@dataclass(frozen=True)
class GoalOutcome:
    """The terminal status of one goal, to be recorded once (FaultLedger.record_goal_outcome)."""

    action: str
    goal_id: str
    """UUID text (``goal_text``)."""
    status: str
    """SUCCEEDED, ABORTED or CANCELED."""
    stamp_ns: int
    """When the bridge first saw the terminal status (the receive time of that array): the
    outcome belongs to the period the goal ended in. (``goal_info.stamp`` is the time the
    server *accepted* the goal; a status array carries no end time.)"""


class RecordedGoals:
    """The goals whose outcome was already handed on, so each goal is recorded once although
    servers republish finished goals in every array.

    A bounded LRU of (action, goal_id): a goal forgotten (more than ``capacity`` newer ones)
    or a restarted bridge sends an outcome again, which the fault manager answers as a
    duplicate and does not store (it keys outcomes by action and goal id).
    """

    def __init__(self, capacity: int) -> None:
        self.capacity = max(capacity, 1)
        self._recorded: OrderedDict[tuple[str, bytes], None] = OrderedDict()

    def new_outcomes(self, action: str, goals: Iterable[Goal], received_ns: int
                     ) -> list[GoalOutcome]:
        """Outcomes of the terminal goals among ``goals`` not handed on yet, at the time the
        array showing them was received."""
        out = []
        for goal_id, status in goals:
            if status not in TERMINAL:
                continue
            key = (action, goal_id)
            if key in self._recorded:
                self._recorded.move_to_end(key)
                continue
            self._recorded[key] = None
            if len(self._recorded) > self.capacity:
                self._recorded.popitem(last=False)
            out.append(GoalOutcome(action, goal_text(goal_id), STATUS_NAMES[status],
                                   received_ns))
        return out

    def __len__(self) -> int:
        return len(self._recorded)


class SeenGoals:
    """Bounded LRU of goal_id:status already logged: keeps log lines from repeating. It has no
    say in fault decisions (ActionTracker judges the arrays themselves)."""

    def __init__(self, capacity: int) -> None:
        self.capacity = max(capacity, 1)
        self._seen: OrderedDict[tuple[str, bytes, int], None] = OrderedDict()

    def first_time(self, action: str, goal_id: bytes, status: int) -> bool:
        key = (action, goal_id, status)
        if key in self._seen:
            self._seen.move_to_end(key)
            return False
        self._seen[key] = None
        if len(self._seen) > self.capacity:
            self._seen.popitem(last=False)
        return True

    def __len__(self) -> int:
        return len(self._seen)
