"""``serve``'s Fast DDS profile (ros/dds_profile.py): used unless the user chose otherwise."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from faultledger.ros.dds_profile import (
    ANNOUNCE_SEC,
    ANSWER_HEARTBEAT_SEC,
    CWD_PROFILE,
    PROFILE,
    PROFILE_ENV,
    use_manager_profile,
)

NS = {"dds": "http://www.eprosima.com"}


def test_the_shipped_profile_announces_as_documented() -> None:
    root = ET.parse(PROFILE).getroot()
    participant = root.find("dds:profiles/dds:participant", NS)
    assert participant is not None and participant.get("is_default_profile") == "true"
    announce = participant.find(
        "dds:rtps/dds:builtin/dds:discovery_config/dds:leaseAnnouncement", NS)
    assert announce is not None
    seconds = int(announce.findtext("dds:sec", "0", NS)) + int(
        announce.findtext("dds:nanosec", "0", NS)) / 1e9
    assert seconds == ANNOUNCE_SEC


def test_the_service_answers_are_repaired_within_the_documented_heartbeat() -> None:
    """rmw_fastrtps gives every service's reply writer the profile named "service"."""
    root = ET.parse(PROFILE).getroot()
    [writer] = [w for w in root.findall("dds:profiles/dds:data_writer", NS)
                if w.get("profile_name") == "service"]
    period = writer.find("dds:times/dds:heartbeatPeriod", NS)
    assert period is not None
    seconds = int(period.findtext("dds:sec", "0", NS)) + int(
        period.findtext("dds:nanosec", "0", NS)) / 1e9
    assert seconds == ANSWER_HEARTBEAT_SEC


def test_used_by_default(tmp_path: Path) -> None:
    env: dict[str, str] = {}
    said = use_manager_profile(env, cwd=tmp_path)
    assert env == {PROFILE_ENV: str(PROFILE)}
    assert said == "dds_profile=faultledger (announces every 0.5 s)"


def test_a_users_profile_file_is_kept(tmp_path: Path) -> None:
    env = {PROFILE_ENV: "/etc/robot/dds.xml"}
    said = use_manager_profile(env, cwd=tmp_path)
    assert env == {PROFILE_ENV: "/etc/robot/dds.xml"}
    assert said == f"dds_profile=/etc/robot/dds.xml ({PROFILE_ENV})"


def test_a_profile_in_the_working_directory_is_kept(tmp_path: Path) -> None:
    (tmp_path / CWD_PROFILE).write_text("<dds/>")
    env: dict[str, str] = {}
    assert use_manager_profile(env, cwd=tmp_path) == f"dds_profile=./{CWD_PROFILE}"
    assert env == {}


def test_other_middleware_gets_nothing(tmp_path: Path) -> None:
    env = {"RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp"}
    assert use_manager_profile(env, cwd=tmp_path) == "dds_profile=none (rmw_cyclonedds_cpp)"
    assert env == {"RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp"}


def test_a_users_profile_path_is_shown_on_one_line(tmp_path: Path) -> None:
    env = {PROFILE_ENV: "/tmp/evil\nfault_manager ready: forged.xml"}
    said = use_manager_profile(env, cwd=tmp_path)
    assert "\n" not in said and said.startswith("dds_profile=/tmp/evil")
    assert env[PROFILE_ENV] == "/tmp/evil\nfault_manager ready: forged.xml"  # used as given
