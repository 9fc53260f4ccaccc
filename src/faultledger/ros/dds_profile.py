"""The Fast DDS profile ``serve`` runs with, so a second manager is noticed in 2 s, not 5, and
a lost service answer is sent again within 50 ms (ANSWER_HEARTBEAT_SEC).

A process only learns of a running participant from that participant's periodic announcement
(Fast DDS: every 3 s; a newcomer's own announcements are not answered at once). ``serve``
announces every 0.5 s instead (fastdds_manager.xml), so another ``serve`` sees it within
about 0.5 s (measured on 2 cores: its ``report_fault`` 0-0.43 s after a new node was
created, in 12 starts; 0-2.5 s with the default period).
A profile the user chose (FASTRTPS_DEFAULT_PROFILES_FILE, or DEFAULT_FASTRTPS_PROFILES.xml
in the working directory, which Fast DDS loads by itself) is left alone; docs/ros.md.
"""

from __future__ import annotations

import os
from collections.abc import MutableMapping
from pathlib import Path

from faultledger.ros.guard import clip

PROFILE_ENV = "FASTRTPS_DEFAULT_PROFILES_FILE"
CWD_PROFILE = "DEFAULT_FASTRTPS_PROFILES.xml"
PROFILE = Path(__file__).resolve().parent / "fastdds_manager.xml"
ANNOUNCE_SEC = 0.5
"""The announcement period in PROFILE."""
ANSWER_HEARTBEAT_SEC = 0.05
"""The heartbeat period of the service answers' writers in PROFILE (Fast DDS: 3 s). A reliable
writer sends an answer again only after a heartbeat shows the reader missed it: while a 16 MB
statistics answer filled the shared-memory segment, a report's answer was lost and arrived
1.5-1.8 s late (3 of 8 runs of tests/ros/test_read_pool.py); with 50 ms, none in 18."""


def use_manager_profile(env: MutableMapping[str, str] | None = None,
                        cwd: Path | None = None) -> str:
    """Point Fast DDS at PROFILE unless another RMW or a profile of the user's is in use;
    returns what the ``fault_manager network:`` line says about it. Call before rclpy.init."""
    env = os.environ if env is None else env
    rmw = env.get("RMW_IMPLEMENTATION", "") or "rmw_fastrtps_cpp"
    if not rmw.startswith("rmw_fastrtps"):
        return f"dds_profile=none ({rmw})"
    if env.get(PROFILE_ENV):
        return f"dds_profile={clip(env[PROFILE_ENV], 120)} ({PROFILE_ENV})"
    if ((cwd or Path.cwd()) / CWD_PROFILE).is_file():
        return f"dds_profile=./{CWD_PROFILE}"
    env[PROFILE_ENV] = str(PROFILE)
    return f"dds_profile=faultledger (announces every {ANNOUNCE_SEC:g} s)"
