"""A hardware publisher process for the hardware-status bridge tests: like ros2_control's status
publisher, it republishes its current ``hardware_status_msgs/HardwareStatus`` periodically on
/hardware_status, and takes orders on stdin.

stdin, one JSON object per line:

* ``{"set": status}``: the message to publish from now on (published at once); answers
  ``set``. ``status`` is ``{"hw": hardware_id, "devices": [device, ...], "extra_devices": n}``
  with ``device`` = ``{"id", "generic": [{"health", "errors", "power", "connect",
  "details": {k: v}}], "canopen": [{"node", "nmt", "dsp", "emcy"}], "ethercat": [{"position",
  "al_state", "has_error", "al_status_code"}]}`` (all keys optional); ``extra_devices`` appends
  that many healthy devices ``x0``, ``x1``, ... (a huge array).
* ``{"ticks": n}``: answers ``ticked`` once the current message was published n more times.

stdout: ``matched`` once a subscriber is matched, then the answers above. argv[1]: the period
in seconds (default 0.05). EOF on stdin ends the process.
"""

from __future__ import annotations

import json
import os
import select
import sys
import time
from typing import Any

import rclpy
from diagnostic_msgs.msg import KeyValue  # type: ignore[import-untyped,unused-ignore]
from hardware_status_msgs.msg import (  # type: ignore[import-untyped,unused-ignore]
    CANopenState,
    EtherCATState,
    GenericState,
    HardwareDeviceStatus,
    HardwareStatus,
)
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.utilities import try_shutdown


def generic(g: dict[str, Any]) -> Any:
    return GenericState(
        health_status=int(g.get("health", GenericState.HEALTH_OK)),
        error_domain=[int(e) for e in g.get("errors", [])],
        operational_mode=GenericState.MODE_AUTO,
        power_state=int(g.get("power", GenericState.POWER_ON)),
        connectivity_status=int(g.get("connect", GenericState.CONNECT_UP)),
        manufacturer="ACME", model="J-1",
        state_details=[KeyValue(key=k, value=v) for k, v in g.get("details", {}).items()])


def build(spec: dict[str, Any]) -> Any:
    message = HardwareStatus(hardware_id=spec.get("hw", ""))
    devices = list(spec.get("devices", []))
    devices += [{"id": f"x{i}", "generic": [{}]} for i in range(int(spec.get("extra_devices", 0)))]
    for d in devices:
        message.hardware_device_states.append(HardwareDeviceStatus(
            device_id=d.get("id", ""),
            generic_hardware_status=[generic(g) for g in d.get("generic", [])],
            canopen_states=[CANopenState(node_id=int(c.get("node", 1)),
                                         nmt_state=int(c.get("nmt", CANopenState.NMT_OPERATIONAL)),
                                         dsp_402_state=int(c.get("dsp", 4)),
                                         last_emcy_code=int(c.get("emcy", 0)))
                            for c in d.get("canopen", [])],
            ethercat_states=[EtherCATState(slave_position=int(e.get("position", 0)),
                                           vendor_id="0x00000002", product_code="0x0c1e3052",
                                           al_state=int(e.get("al_state", 8)),
                                           has_error=bool(e.get("has_error", False)),
                                           al_status_code=int(e.get("al_status_code", 0)))
                             for e in d.get("ethercat", [])]))
    return message


def main() -> int:
    period = float(sys.argv[1]) if len(sys.argv) > 1 else 0.05
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node(f"test_hardware_publisher_{os.getpid()}", context=context)
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    publisher = node.create_publisher(HardwareStatus, "/hardware_status", qos)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    current: Any = None
    published = 0
    tick_target: int | None = None
    matched = False
    next_at = time.monotonic()
    try:
        while True:
            executor.spin_once(timeout_sec=0.005)
            if not matched and publisher.get_subscription_count() > 0:
                matched = True
                print("matched", flush=True)
            now = time.monotonic()
            if current is not None and now >= next_at:
                current.header.stamp = node.get_clock().now().to_msg()
                publisher.publish(current)
                published += 1
                next_at = now + period
            if tick_target is not None and published >= tick_target:
                print("ticked", flush=True)
                tick_target = None
            if select.select([sys.stdin], [], [], 0)[0]:
                line = sys.stdin.readline()
                if not line:
                    return 0
                order = json.loads(line)
                if "set" in order:
                    current = build(order["set"])
                    next_at = 0.0  # publish at once
                    print("set", flush=True)
                elif "ticks" in order:
                    tick_target = published + int(order["ticks"])
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    finally:
        executor.shutdown()
        node.destroy_node()
        try_shutdown(context=context)


if __name__ == "__main__":
    sys.exit(main())
