"""Who can reach a ROS process: its discovery scope and security, as rcl will apply them.

rclpy has no call that returns the discovery options in force, so ``scope`` reads the same
environment variables as rcl (Jazzy, ``rcl/discovery_options.c`` and ``rcl/init.c``) with
the same rules; docs/ros.md "Network scope and security".
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass

from faultledger.ros.guard import clip

RANGES = ("OFF", "LOCALHOST", "SUBNET", "SYSTEM_DEFAULT")
DEFAULT_RANGE = "SUBNET"
"""Jazzy's default when ROS_AUTOMATIC_DISCOVERY_RANGE is unset or empty (measured with these
wheels: SPDP multicast on every interface, docs/ros-wheels.md)."""


@dataclass(frozen=True)
class Scope:
    discovery_range: str
    why: str
    static_peers: tuple[str, ...]
    security: bool
    security_strategy: str
    keystore: str

    def describe(self, domain_id: int, rmw: str) -> str:
        """One line: ``discovery=... static_peers=... domain_id=... rmw=... security=...``."""
        peers = ",".join(clip(p, 80) for p in self.static_peers) or "none"
        if self.security:  # requested: whether it is in force depends on the keystore
            security = (f"requested ({self.security_strategy}, keystore "
                        f"{clip(self.keystore, 120) or 'unset'})")
        else:
            security = "off"
        return (f"discovery={self.discovery_range} ({self.why}) static_peers={peers} "
                f"domain_id={domain_id} rmw={rmw} security={security}")


def scope(env: Mapping[str, str] | None = None) -> Scope:
    """The discovery range, static peers and security settings rcl derives from ``env``."""
    env = os.environ if env is None else env
    value = env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "")
    peers: tuple[str, ...]
    if env.get("ROS_LOCALHOST_ONLY", "") == "1":  # deprecated; wins over the range and peers
        discovery, why, peers = "LOCALHOST", "ROS_LOCALHOST_ONLY=1, deprecated", ()
    else:
        if value == "":
            discovery, why = DEFAULT_RANGE, "default: ROS_AUTOMATIC_DISCOVERY_RANGE unset"
        elif value in RANGES:
            discovery, why = value, "ROS_AUTOMATIC_DISCOVERY_RANGE"
        else:
            discovery = "LOCALHOST"
            why = f"ROS_AUTOMATIC_DISCOVERY_RANGE={clip(value, 40)} is invalid; rcl assumes this"
        peers = () if discovery == "OFF" else tuple(
            p for p in env.get("ROS_STATIC_PEERS", "").split(";") if p)
    strategy = "Enforce" if env.get("ROS_SECURITY_STRATEGY", "") == "Enforce" else "Permissive"
    return Scope(discovery, why, peers, env.get("ROS_SECURITY_ENABLE", "") == "true",
                 strategy, env.get("ROS_SECURITY_KEYSTORE", ""))
