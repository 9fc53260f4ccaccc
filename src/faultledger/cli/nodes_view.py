"""``faultledger nodes``: a live table of every node heard on ``/nodemon/state``.

The successor of nodemon_tui. One subscription (the bridge's QoS), a ``rich`` view redrawn
about twice a second; ages come from the steady clock at receipt, never from message stamps,
so a node with a skewed clock still shows how long ago it was heard. A node silent for longer
than the heartbeat timeout shows LOST, by the node-state bridge's own rule
(``node_state_mapping.heartbeat_lost``). Each node also shows its last state other than
RUNNING (a one-off WARNING, an ERROR it recovered from) with its age.

On a terminal, keys act at once: ``s`` cycles the sort (name, state, age), ``f`` or ``/``
filters (a node name substring, or a state name such as ``lost``; empty clears it), ``q``
quits. ``--once`` takes the same as options (``--sort``, ``--filter``, ``--state``).
"""

from __future__ import annotations

import contextlib
import os
import select
import sys
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions
from rich.console import Console, Group, RenderableType
from rich.live import Live
from rich.table import Table
from rich.text import Text

from faultledger.cli.safe_text import cell, printable
from faultledger.ros.bridges.node_state import QOS, node_state_type
from faultledger.ros.bridges.node_state_mapping import (
    HEARTBEAT_TIMEOUT_SEC,
    RUNNING,
    STARTING,
    STATE_NAMES,
    WARNING,
    heartbeat_lost,
)
from faultledger.ros.guard import guard_callback
from faultledger.ros.network import scope

LOST = "LOST"
STATE_STYLES: dict[str, str] = {
    "STARTING": "cyan", "STOPPING": "dim", "RUNNING": "green", "ERROR": "bold red",
    "RECOVERING": "yellow", "FATAL": "bold white on red", "WARNING": "bold yellow",
    LOST: "bold white on red",
}
STATE_ORDER = (LOST, "FATAL", "ERROR", "RECOVERING", "WARNING", "STARTING", "STOPPING",
               "RUNNING")
"""Sort by state: the worst first."""
SORT_KEYS = ("name", "state", "age")
REFRESH_SEC = 0.5
COLUMNS = ("node", "package", "type", "state", "age", "message", "last")
"""The cells of a row (``rows``) and the table's columns, in this order."""
DROP_ORDER = ("message", "type", "package")
"""Columns dropped, in this order, until the table fits the terminal; a node name is never
wrapped or cut while anything else can go."""

def state_name(state: int) -> str:
    return STATE_NAMES.get(state, f"UNKNOWN({state})")


def short_age(seconds: float) -> str:
    """``0.4s``, ``12s``, ``5m03s``, ``2h07m``: short enough for a narrow column."""
    if seconds < 10:
        return f"{max(seconds, 0.0):.1f}s"
    if seconds < 60:
        return f"{seconds:.0f}s"
    if seconds < 3600:
        return f"{int(seconds // 60)}m{int(seconds % 60):02d}s"
    return f"{int(seconds // 3600)}h{int(seconds % 3600 // 60):02d}m"


@dataclass
class Event:
    """The last message of a node whose state was not RUNNING (nor STARTING)."""

    state: int
    received: float
    message: str


@dataclass
class Seen:
    """What is known of one node; ``state`` is its sustained state (a WARNING is one-off and
    only becomes ``last``), ``received`` when (steady clock) it was last heard."""

    nodename: str
    package: str
    nodetype: str
    state: int
    machine_message: str
    human_message: str
    received: float
    last: Event | None = None


def message_text(human: str, machine: str) -> str:
    return f"{human} [{machine}]" if human and machine else human or machine


class NodesView:
    """Collects NodeState messages; ``render()`` shows what is known now."""

    def __init__(self, topic: str = "/nodemon/state",
                 timeout_sec: float = HEARTBEAT_TIMEOUT_SEC, sort: str = "name",
                 name_filter: str = "", states: Iterable[str] = ()) -> None:
        self.topic = topic
        self.timeout_sec = timeout_sec
        self.nodes: dict[str, Seen] = {}
        self.sort = sort if sort in SORT_KEYS else "name"
        self.name_filter = name_filter
        self.states = {s.upper() for s in states}
        self.started = time.monotonic()
        self.started_wall = datetime.now().astimezone()

    def on_state(self, message: Any) -> None:
        if not message.nodename:
            return
        now = time.monotonic()
        state = int(message.state)
        text = message_text(message.human_message, message.machine_message)
        seen = self.nodes.get(message.nodename)
        if seen is None:
            seen = self.nodes[message.nodename] = Seen(
                message.nodename, message.package, message.nodetype, state,
                message.machine_message, message.human_message, now)
        seen.package, seen.nodetype, seen.received = message.package, message.nodetype, now
        if state not in (RUNNING, STARTING):
            seen.last = Event(state, now, text)
        if state != WARNING:  # one-off: the next heartbeat carries the sustained state
            seen.state = state
            seen.machine_message, seen.human_message = (message.machine_message,
                                                        message.human_message)

    # -- what is shown --------------------------------------------------------------------------
    def shown_state(self, seen: Seen, now: float) -> str:
        """LOST by the bridge's rule, else the sustained state's name."""
        if heartbeat_lost(seen.state, seen.received, now, self.timeout_sec):
            return LOST
        return state_name(seen.state)

    def set_filter(self, text: str) -> None:
        """A state name filters by state, anything else by name substring; "" clears."""
        text = text.strip()
        if text.upper() in STATE_ORDER:
            self.states, self.name_filter = {text.upper()}, ""
        else:
            self.states, self.name_filter = set(), text

    def cycle_sort(self) -> None:
        self.sort = SORT_KEYS[(SORT_KEYS.index(self.sort) + 1) % len(SORT_KEYS)]

    def visible(self, now: float) -> list[Seen]:
        """The nodes passing the filters, in the chosen order."""
        needle = self.name_filter.lower()
        shown = [s for s in self.nodes.values()
                 if needle in s.nodename.lower()
                 and (not self.states or self.shown_state(s, now) in self.states)]
        if self.sort == "state":
            rank = {name: i for i, name in enumerate(STATE_ORDER)}
            shown.sort(key=lambda s: (rank.get(self.shown_state(s, now), 0), s.nodename))
        elif self.sort == "age":
            shown.sort(key=lambda s: (s.received, s.nodename))  # longest silent first
        else:
            shown.sort(key=lambda s: s.nodename)
        return shown

    def rows(self, now: float | None = None) -> list[list[Text]]:
        """The cells (``COLUMNS``), one list per visible node. Names, package, type
        and messages come from any publisher: shown literally (``safe_text.cell``: never
        markup, control characters escaped, one line per node)."""
        now = time.monotonic() if now is None else now
        rows: list[list[Text]] = []
        for seen in self.visible(now):
            age = now - seen.received
            state = self.shown_state(seen, now)
            stale = state == LOST
            last = Text("")
            if seen.last is not None:
                name = state_name(seen.last.state)
                last = Text.assemble((name, STATE_STYLES.get(name, "magenta")),
                                     f" {short_age(now - seen.last.received)} ago")
            message = message_text(seen.human_message, seen.machine_message)
            if seen.last is not None and seen.last.message and seen.last.state == WARNING:
                message = message or seen.last.message
            rows.append([cell(seen.nodename), cell(seen.package), cell(seen.nodetype),
                         cell(state, STATE_STYLES.get(state, "magenta")),
                         cell(short_age(age), "red" if stale else None), cell(message), last])
        return rows

    def counts(self, now: float) -> dict[str, int]:
        counts: dict[str, int] = {}
        for seen in self.nodes.values():
            state = self.shown_state(seen, now)
            counts[state] = counts.get(state, 0) + 1
        return counts

    def summary(self, now: float | None = None) -> Text:
        """``3 nodes: 2 RUNNING 1 LOST | /nodemon/state | since 21:50:03 (12s) | sort name``."""
        now = time.monotonic() if now is None else now
        counts = self.counts(now)
        text = Text(f"{len(self.nodes)} node{'s' if len(self.nodes) != 1 else ''}")
        if counts:
            text.append(":")
        for state in STATE_ORDER:
            if counts.get(state):
                text.append(" ")
                text.append(f"{counts[state]} {state}", STATE_STYLES.get(state, ""))
        for state, count in sorted(counts.items()):
            if state not in STATE_ORDER:
                text.append(f" {count} {printable(state)}")
        text.append(f" | {printable(self.topic)} | since "
                    f"{self.started_wall:%H:%M:%S} ({short_age(now - self.started)})"
                    f" | sort {self.sort}")
        if self.name_filter or self.states:
            shown = self.name_filter or ",".join(sorted(self.states))
            text.append(f" | filter {printable(shown)!r}", "bold")
        return text

    def hint(self, now: float | None = None) -> Text | None:
        """Why the table is empty, when it is."""
        now = time.monotonic() if now is None else now
        if not self.nodes:
            where = scope()
            domain = os.environ.get("ROS_DOMAIN_ID", "0") or "0"
            return Text(
                f"no NodeState on {printable(self.topic)} yet "
                f"({short_age(now - self.started)}): is the publisher library "
                "(faultledger.nodemon.NodeStatePublisher) in your nodes? same topic and "
                "namespace (--topic, --ros-args -r __ns:=...)? same ROS_DOMAIN_ID "
                f"(here {printable(domain)}) and discovery range (here "
                f"{where.discovery_range}, ROS_AUTOMATIC_DISCOVERY_RANGE)?", "yellow")
        if not self.visible(now):
            return Text(f"{len(self.nodes)} node(s) heard, none matches the filter", "yellow")
        return None

    def table(self, now: float | None = None, width: int | None = None) -> Table:
        """The table; with ``width``, columns are dropped (``DROP_ORDER``) until it fits."""
        now = time.monotonic() if now is None else now
        rows = self.rows(now)
        columns = list(COLUMNS)
        if width is not None:
            for column in DROP_ORDER:
                if table_width(columns, rows) <= width:
                    break
                columns.remove(column)
        table = Table(title=f"nodes on {printable(self.topic)} ({len(self.nodes)})",
                      expand=False)
        for column in columns:
            table.add_column(column, no_wrap=column != "message",
                             overflow="fold" if column == "message" else "ellipsis")
        keep = [COLUMNS.index(c) for c in columns]
        for row in rows:
            table.add_row(*(row[i] for i in keep))
        return table

    def render(self, now: float | None = None, width: int | None = None,
               footer: Text | None = None) -> RenderableType:
        now = time.monotonic() if now is None else now
        parts: list[RenderableType] = [self.summary(now)]
        hint = self.hint(now)
        if self.nodes:
            parts.append(self.table(now, width))
        if hint is not None:
            parts.append(hint)
        if footer is not None:
            parts.append(footer)
        return Group(*parts)


def table_width(columns: Sequence[str], rows: list[list[Text]]) -> int:
    """Width of a rich table with these columns (box borders, one space of padding)."""
    total = 1
    for column in columns:
        i = COLUMNS.index(column)
        total += max([len(column), *(row[i].cell_len for row in rows)]) + 3
    return total


class Keys:
    """Key presses from a terminal, without waiting: cbreak mode while open (restored after)."""

    def __init__(self) -> None:
        self.fd = sys.stdin.fileno() if sys.stdin.isatty() else -1
        self._saved: Any = None

    def __enter__(self) -> Keys:
        if self.fd >= 0:
            import termios
            import tty

            self._saved = termios.tcgetattr(self.fd)
            tty.setcbreak(self.fd)
        return self

    def __exit__(self, *_exc: object) -> None:
        if self._saved is not None:
            import termios

            termios.tcsetattr(self.fd, termios.TCSADRAIN, self._saved)

    def read(self) -> str:
        if self.fd < 0 or not select.select([self.fd], [], [], 0)[0]:
            return ""
        return os.read(self.fd, 64).decode("utf-8", "replace")


class Controller:
    """Interactive keys: ``s`` sort, ``f`` or ``/`` filter (Enter applies, Esc cancels), ``q``
    quit."""

    def __init__(self, view: NodesView) -> None:
        self.view = view
        self.entry: str | None = None
        self.quit = False

    def feed(self, keys: str) -> bool:
        """Handle ``keys``; True when the view should be redrawn at once."""
        changed = False
        for key in keys:
            changed = True
            if self.entry is not None:
                if key in "\r\n":
                    self.view.set_filter(self.entry)
                    self.entry = None
                elif key == "\x1b":
                    self.entry = None
                elif key in "\x7f\b":
                    self.entry = self.entry[:-1]
                elif key.isprintable():
                    self.entry += key
            elif key in "qQ":
                self.quit = True
            elif key == "s":
                self.view.cycle_sort()
            elif key in "f/":
                self.entry = ""
            elif key == "\x1b":
                self.view.set_filter("")
            else:
                changed = False
        return changed

    def footer(self) -> Text:
        if self.entry is not None:
            return Text(f"filter (name or state, Enter, Esc): {printable(self.entry)}_", "bold")
        return Text("s sort | f or / filter | Esc clear filter | q quit", "dim")


def run_nodes_view(topic: str, once: bool, listen_sec: float, ros_args: list[str], *,
                   sort: str = "name", name_filter: str = "", states: Sequence[str] = (),
                   timeout_sec: float = HEARTBEAT_TIMEOUT_SEC) -> int:
    """Listen on ``topic``; ``once``: print one snapshot after ``listen_sec`` and return,
    otherwise redraw until ``q`` or Ctrl-C."""
    context = Context()
    rclpy.init(args=["faultledger", *ros_args], context=context,
               signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node(f"faultledger_nodes_view_{os.getpid()}", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    view = NodesView(topic, timeout_sec, sort, name_filter, states)
    node.create_subscription(node_state_type(), topic,
                             guard_callback(view.on_state, node.get_logger(), topic), QOS)
    try:
        if once:
            deadline = time.monotonic() + listen_sec
            while (left := deadline - time.monotonic()) > 0:
                executor.spin_once(timeout_sec=min(left, 0.1))
            console = Console() if sys.stdout.isatty() else Console(width=160)
            console.print(view.render(width=console.width))
            return 0
        console = Console()
        controller = Controller(view)
        with Keys() as keys, _live(view, console, controller) as live:
            next_draw = time.monotonic() + REFRESH_SEC
            while not controller.quit:
                executor.spin_once(timeout_sec=0.05)
                redraw = controller.feed(keys.read())
                if redraw or time.monotonic() >= next_draw:
                    live.update(view.render(width=console.width, footer=controller.footer()),
                                refresh=True)
                    next_draw = time.monotonic() + REFRESH_SEC
        return 0
    except KeyboardInterrupt:
        return 0
    finally:
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()


@contextlib.contextmanager
def _live(view: NodesView, console: Console, controller: Controller) -> Iterator[Live]:
    with Live(view.render(width=console.width, footer=controller.footer()), console=console,
              auto_refresh=False, screen=False, transient=False) as live:
        yield live
