"""Start bridges: one node, one FaultReporter and one Bridge each, on a given executor."""

from __future__ import annotations

import importlib
import signal
import threading
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import Any, Protocol

import rclpy
from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import ok, try_shutdown

from faultledger.errors import ConfigError
from faultledger.ros.bridges import BRIDGES
from faultledger.ros.bridges.settings import normalise, read_yaml
from faultledger.ros.guard import guard_callback
from faultledger.ros.reporter import FaultReporter


class Bridge(Protocol):
    def close(self) -> None: ...


@dataclass
class RunningBridge:
    name: str
    node: Node
    reporter: FaultReporter
    bridge: Bridge

    def close(self) -> None:
        self.bridge.close()
        self.reporter.destroy()
        self.node.destroy_node()


def canonical(name: str) -> str:
    """``action-status`` and ``action_status`` name the same bridge."""
    key = name.replace("-", "_")
    if key not in BRIDGES:
        known = ", ".join(k.replace("_", "-") for k in BRIDGES)
        raise ConfigError(f"unknown bridge {name!r}; known bridges: {known}")
    return key


def settings_from(entry: Mapping[str, Any], base: Path | None = None) -> dict[str, Any]:
    """A bridge's raw settings: its ``config`` file (relative to ``base``), then inline keys."""
    raw = dict(entry)
    raw.pop("enabled", None)
    config = raw.pop("config", None)
    if config is None:
        return raw
    path = Path(config)
    if base is not None and not path.is_absolute():
        path = base / path
    return {**read_yaml(path), **raw}


def start_bridge(name: str, raw: Mapping[str, Any], executor: Executor,
                 manager: str = "/fault_manager") -> RunningBridge:
    """Create the bridge's node (added to ``executor``), its reporter and the bridge."""
    key = canonical(name)
    module: Any = importlib.import_module(BRIDGES[key])
    node = Node(module.NODE_NAME)
    settings = normalise(module.Settings, raw,
                         lambda message: node.get_logger().warning(message), key)
    reporter = FaultReporter(node, node.get_fully_qualified_name(), manager=manager,
                             local_filtering=False)
    bridge = module.Bridge(node, settings, reporter)
    executor.add_node(node)
    return RunningBridge(key, node, reporter, bridge)


def run_bridge(name: str, config: Path | None, ros_args: list[str]) -> int:
    """``faultledger bridge NAME``: one bridge in its own process until SIGINT/SIGTERM."""
    raw = read_yaml(config) if config is not None else {}
    canonical(name)  # an unknown name fails before ROS starts
    rclpy.init(args=["faultledger", *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()

    def on_signal(_signum: int, _frame: FrameType | None) -> None:
        stop.set()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    executor = SingleThreadedExecutor()
    running: RunningBridge | None = None
    try:
        running = start_bridge(name, raw, executor)
        print(f"bridge ready: {running.name} as {running.node.get_fully_qualified_name()}",
              flush=True)
        # Callbacks never raise (guard.py); this keeps rclpy's own steps from ending us.
        spin_once = guard_callback(executor.spin_once, running.node.get_logger(), "executor")
        while not stop.is_set() and ok():
            spin_once(0.1)
    finally:
        if running is not None:
            running.close()
        executor.shutdown()
        try_shutdown()
    return 0
