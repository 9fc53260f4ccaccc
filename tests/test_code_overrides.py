"""Per-fault-code pattern overrides of the debounce policy, and the shipped configuration that
makes the bridges' faults heal on their PASSED (issue "Every report in the log", part 5)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Callable
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest

from faultledger import FaultLedger, FaultStatus, Policy
from faultledger.errors import ConfigError
from faultledger.service.config import load_settings

OpenLedger = Callable[..., FaultLedger]
ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "config" / "faultledger.yaml"
T0 = datetime(2026, 11, 21, 22, 0, tzinfo=UTC)

HEALING = {"healing_enabled": True, "healing_threshold": 0}


def status(ledger: FaultLedger, code: str) -> FaultStatus:
    fault = ledger.get_fault(code)
    assert fault is not None
    return fault.status


def test_a_matching_code_pattern_heals_on_the_first_passed(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(code_overrides={"HW_*": HEALING}))

    ledger.report("HW_ARM_EMERGENCY_STOP", "FAILED", 2, "pressed", "/arm", at=T0)
    confirmed = status(ledger, "HW_ARM_EMERGENCY_STOP")
    ledger.report("HW_ARM_EMERGENCY_STOP", "PASSED", 0, "", "/arm", at=T0 + timedelta(seconds=9))

    assert (confirmed, status(ledger, "HW_ARM_EMERGENCY_STOP")) == (FaultStatus.CONFIRMED,
                                                                    FaultStatus.HEALED)


def test_other_codes_keep_the_global_policy(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(code_overrides={"HW_*": HEALING}))

    ledger.report("MOTOR_OVERHEAT", "FAILED", 2, "", "/motor", at=T0)
    ledger.report("MOTOR_OVERHEAT", "PASSED", 0, "", "/motor", at=T0 + timedelta(seconds=1))

    assert status(ledger, "MOTOR_OVERHEAT") is FaultStatus.CONFIRMED


def test_the_most_specific_pattern_applies() -> None:
    policy = Policy(code_overrides={"HW_*": HEALING,
                                    "HW_ARM_*": {"confirmation_threshold": -3},
                                    "*_STOP": {"healing_threshold": 7}})

    arm = policy.resolve("/arm", "HW_ARM_EMERGENCY_STOP")
    base = policy.resolve("/base", "HW_BASE_EMERGENCY_STOP")
    other = policy.resolve("/x", "LIDAR_STOP")

    assert (arm.confirmation_threshold, arm.healing_enabled) == (-3, False)
    assert (base.healing_enabled, base.healing_threshold) == (True, 0)
    assert (other.healing_enabled, other.healing_threshold) == (False, 7)


def test_a_source_override_wins_over_a_code_pattern_for_the_fields_it_sets() -> None:
    policy = Policy(code_overrides={"HW_*": HEALING},
                    overrides={"/arm": {"healing_threshold": 2}})

    params = policy.resolve("/arm/left", "HW_ARM_EMERGENCY_STOP")

    assert (params.healing_enabled, params.healing_threshold) == (True, 2)


def test_code_overrides_are_recorded_and_replayed_after_a_restart(open_ledger: OpenLedger
                                                                   ) -> None:
    policy = Policy(code_overrides={"ACTION_*": HEALING})
    first = open_ledger(policy)
    first.report("ACTION_NAV_ABORTED", "FAILED", 2, "", "/nav", at=T0)
    first.report("ACTION_NAV_ABORTED", "PASSED", 0, "", "/nav", at=T0 + timedelta(seconds=1))
    first.close()

    reopened = open_ledger()  # no policy given: the log's own applies

    assert reopened.policy.code_overrides == policy.code_overrides
    assert status(reopened, "ACTION_NAV_ABORTED") is FaultStatus.HEALED
    assert reopened.verify().ok


def test_a_healed_bridge_fault_is_cleared_at_startup_when_the_pattern_goes(
        open_ledger: OpenLedger) -> None:
    first = open_ledger(Policy(code_overrides={"NODE_*": HEALING}))
    first.report("NODE_PLANNER_ERROR", "FAILED", 2, "", "/planner", at=T0)
    first.report("NODE_PLANNER_ERROR", "PASSED", 0, "", "/planner", at=T0 + timedelta(seconds=1))
    first.close()

    kept = open_ledger(Policy(code_overrides={"NODE_*": HEALING}))
    kept_status = status(kept, "NODE_PLANNER_ERROR")
    kept.close()
    medkit = open_ledger(Policy())

    assert kept_status is FaultStatus.HEALED
    assert status(medkit, "NODE_PLANNER_ERROR") is FaultStatus.CLEARED


def test_the_shipped_configuration_heals_the_bridges_faults_only() -> None:
    policy = load_settings(SHIPPED).policy

    for code in ("HW_ARM_EMERGENCY_STOP", "ACTION_NAVIGATE_ABORTED", "NODE_PLANNER_HEARTBEAT_LOST"):
        params = policy.resolve("/any", code)
        assert (params.healing_enabled, params.healing_threshold) == (True, 0), code
    medkit = policy.resolve("/any", "MOTOR_OVERHEAT")
    assert (medkit.confirmation_threshold, medkit.healing_enabled) == (-1, False)


def test_an_e_stop_pressed_and_released_counts_its_real_downtime(tmp_path: Path) -> None:
    """The shift report's active time: pressed for 90 s, not "until somebody clears it"."""
    url = f"sqlite:///{tmp_path / 'faults.db'}"
    with FaultLedger.open(url, policy=load_settings(SHIPPED).policy) as ledger:
        ledger.report("HW_ARM_EMERGENCY_STOP", "FAILED", 3, "", "/arm", at=T0)
        ledger.report("HW_ARM_EMERGENCY_STOP", "PASSED", 0, "", "/arm",
                      at=T0 + timedelta(seconds=90))
        [row] = ledger.stats(by="shift", since="2026-11-21/night", until="2026-11-21/night",
                             as_of=T0 + timedelta(hours=8))

    assert (row.activations, row.active_seconds) == (1, 90.0)


@pytest.mark.parametrize(("text", "words"), [
    ('policy: {code_overrides: {"": {healing_enabled: true}}}', "a code pattern must have"),
    ("policy: {code_overrides: {HW_*: {healing: true}}}", "code_overrides.HW_*.healing"),
])
def test_bad_code_overrides_are_refused_naming_the_field(tmp_path: Path, text: str,
                                                         words: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)

    with pytest.raises(ConfigError, match="invalid") as refused:
        load_settings(path)

    assert words in str(refused.value)


def test_the_cli_reports_with_the_shipped_configuration(tmp_path: Path) -> None:
    """The shipped config names its calendar relative to the working directory, as
    `make run` uses it: run where config/ is (a copy of the checkout's)."""
    shutil.copytree(SHIPPED.parent, Path.cwd() / "config")
    db = f"sqlite:///{tmp_path / 'cli.db'}"
    run = [sys.executable, "-m", "faultledger.cli.main"]
    for event in ("FAILED", "PASSED"):
        done = subprocess.run([*run, "report", "HW_BASE_EMERGENCY_STOP", event, "--db", db,
                               "--config", str(SHIPPED)], capture_output=True, text=True,
                              check=False, timeout=60)
        assert done.returncode == 0, done.stderr

    assert "HW_BASE_EMERGENCY_STOP is HEALED" in done.stdout


def test_a_report_whose_summed_fault_time_exceeds_the_shift_says_why(tmp_path: Path) -> None:
    """Two latched faults over a whole 8-hour shift: 16 h of fault time, and a note."""
    db = f"sqlite:///{tmp_path / 'long.db'}"
    with FaultLedger.open(db, policy=Policy()) as ledger:
        for code in ("MOTOR_OVERHEAT", "LIDAR_DIRTY"):
            ledger.report(code, "FAILED", 3, "", "/robot", at=T0 - timedelta(hours=1))
    run = [sys.executable, "-m", "faultledger.cli.main", "report-shift", "2026-11-21/night",
           "--db", db, "--as-of", "2026-11-22T12:00Z"]
    html = tmp_path / "night.html"
    done = subprocess.run([*run, "--html", str(html)], capture_output=True, text=True,
                          check=False, timeout=120, env={**os.environ, "COLUMNS": "200"})

    assert done.returncode == 0, done.stderr
    note = "is summed over faults: several were CONFIRMED at the same time, so it exceeds the 8h"
    assert note in " ".join(done.stdout.split())
    assert "16h" in done.stdout
    assert note in html.read_text()
