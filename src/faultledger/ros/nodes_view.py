"""``faultledger nodes``: a live table of every node heard on ``/nodemon/state``.

The successor of nodemon_tui. One subscription (the bridge's QoS), a ``rich`` table redrawn
about twice a second; ages come from the steady clock at receipt, never from message stamps,
so a node with a skewed clock still shows how long ago it was heard.
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass
from typing import Any

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions
from rich.console import Console
from rich.live import Live
from rich.table import Table
from rich.text import Text

from faultledger.cli.safe_text import cell
from faultledger.ros.bridges.node_state import QOS, node_state_type
from faultledger.ros.bridges.node_state_mapping import (
    ERROR,
    FATAL,
    RECOVERING,
    RUNNING,
    STARTING,
    STATE_NAMES,
    STOPPING,
    WARNING,
)
from faultledger.ros.guard import guard_callback

STATE_STYLES: dict[int, str] = {
    STARTING: "cyan", STOPPING: "dim", RUNNING: "green", ERROR: "bold red",
    RECOVERING: "yellow", FATAL: "bold white on red", WARNING: "bold yellow",
}
STALE_SEC = 5.0
"""Ages above this (the bridge's default heartbeat timeout) are shown in red."""
REFRESH_SEC = 0.5


@dataclass
class Seen:
    """The last message of one node and when (steady clock) it arrived."""

    nodename: str
    package: str
    nodetype: str
    state: int
    machine_message: str
    human_message: str
    received: float


class NodesView:
    """Collects NodeState messages; ``table()`` renders what is known now."""

    def __init__(self) -> None:
        self.nodes: dict[str, Seen] = {}

    def on_state(self, message: Any) -> None:
        if not message.nodename:
            return
        self.nodes[message.nodename] = Seen(
            message.nodename, message.package, message.nodetype, int(message.state),
            message.machine_message, message.human_message, time.monotonic())

    def rows(self, now: float | None = None) -> list[list[Text]]:
        """The table's cells, one list per node in name order. Names, package, type and
        messages come from any publisher: shown literally (``safe_text.cell``: never markup,
        control characters escaped, one line per node)."""
        now = time.monotonic() if now is None else now
        rows: list[list[Text]] = []
        for seen in sorted(self.nodes.values(), key=lambda s: s.nodename):
            age = now - seen.received
            name = STATE_NAMES.get(seen.state, f"UNKNOWN({seen.state})")
            message = seen.human_message
            if seen.machine_message:
                message = f"{message} [{seen.machine_message}]" if message \
                    else seen.machine_message
            stale = age > STALE_SEC and seen.state != STOPPING
            rows.append([cell(seen.nodename), cell(seen.package), cell(seen.nodetype),
                         cell(name, STATE_STYLES.get(seen.state, "magenta")),
                         cell(f"{age:.1f} s", "red" if stale else None), cell(message)])
        return rows

    def table(self, now: float | None = None) -> Table:
        table = Table(title=f"nodes on /nodemon/state ({len(self.nodes)})", expand=False)
        for column in ("node", "package", "type", "state", "age", "message"):
            table.add_column(column, no_wrap=column in ("node", "state", "age"))
        for row in self.rows(now):
            table.add_row(*row)
        return table


def run_nodes_view(topic: str, once: bool, listen_sec: float, ros_args: list[str]) -> int:
    """Listen on ``topic``; ``once``: print one snapshot after ``listen_sec`` and return,
    otherwise redraw until Ctrl-C."""
    context = Context()
    rclpy.init(args=["faultledger", *ros_args], context=context,
               signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node(f"faultledger_nodes_view_{os.getpid()}", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    view = NodesView()
    node.create_subscription(node_state_type(), topic,
                             guard_callback(view.on_state, node.get_logger(), topic), QOS)
    try:
        if once:
            deadline = time.monotonic() + listen_sec
            while (left := deadline - time.monotonic()) > 0:
                executor.spin_once(timeout_sec=min(left, 0.1))
            console = Console() if sys.stdout.isatty() else Console(width=160)
            console.print(view.table())
            return 0
        with Live(view.table(), refresh_per_second=1 / REFRESH_SEC, screen=False) as live:
            next_draw = time.monotonic() + REFRESH_SEC
            while True:
                executor.spin_once(timeout_sec=0.1)
                if time.monotonic() >= next_draw:
                    live.update(view.table())
                    next_draw = time.monotonic() + REFRESH_SEC
    except KeyboardInterrupt:
        return 0
    finally:
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()
